"""The example plugin (examples/tiny_plugin) installed the way a user installs it, then trained,
evaluated, ablated and timed with lfbench's own commands (each in a fresh process, as on the command
line): the trainable-network seam end to end, without lfbench knowing the plugin."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import torch
from helpers import install_example_plugin

from lfbench.data.scene import Benchmark

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    """(example folder copy, environment whose PYTHONPATH holds the installed plugin, site folder)."""
    src, site, env = install_example_plugin(tmp_path_factory.mktemp("tiny_plugin"))
    sys.path.insert(0, str(site))
    yield src, env, site
    sys.path.remove(str(site))
    for name in [m for m in sys.modules if m == "lfbench_tiny" or m.startswith("lfbench_tiny.")]:
        del sys.modules[name]


def lfbench(env: dict, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lfbench", *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=600)


def _ok(proc: subprocess.CompletedProcess) -> str:
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


@pytest.fixture(scope="module")
def trained(plugin, tmp_path_factory):
    src, env, _ = plugin
    out = tmp_path_factory.mktemp("tiny_run") / "run"
    _ok(lfbench(env, "train", src / "train_tiny.toml", "--out", out, "--no-progress"))
    return out


def _tiny_net(config: dict):
    """TinyNet of the installed plugin (on sys.path through the fixture), imported with throw-away
    registries so that this process's method and trainable registries stay as they were."""
    import lfbench.method.registry as registry
    import lfbench.method.trainable as trainable

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(registry, "REGISTRY", registry.MethodRegistry(group=None))
        mp.setattr(trainable, "TRAINABLES", trainable.TrainableRegistry(group=None))
        from lfbench_tiny.plugin import TinyNet
    return TinyNet(**config)


def test_the_plugin_is_listed_with_its_parameters(plugin):
    _, env, _ = plugin
    out = _ok(lfbench(env, "methods"))
    assert "tinycnn: A tiny CNN trained with lfbench train" in out
    assert "weights (Path, required): checkpoint .pt written by lfbench train (OUT/final.pt)" in out


def test_lfbench_train_trains_the_plugin_network(plugin, trained):
    log = [json.loads(line) for line in (trained / "metrics.jsonl").read_text().splitlines()]
    stage1 = [e["loss"] for e in log if e["event"] == "train" and e["stage"] == 1]
    assert len(stage1) == 6  # 150 steps, one entry per 25
    assert stage1[-1] < 0.85 * stage1[0], stage1  # the L1 loss (px) falls by more than 15 %
    assert [e["stage_name"] for e in log if e["event"] == "train"][-1] == "uafl"  # a distribution loss ran too
    final = torch.load(trained / "final.pt", map_location="cpu", weights_only=True)
    assert final["method"] == "tinycnn"
    assert final["config"] == {"channels": 8, "layers": 2, "d_min": -4.0, "d_max": 4.0, "interval": 1.0,
                               "angular": 9}
    assert final["training"]["steps"] == 160 and final["training"]["config"]["method"] == "tinycnn"
    # the same command again: the run is complete, nothing is trained or rewritten
    src, env, _ = plugin
    before = (trained / "final.pt").read_bytes()
    again = lfbench(env, "train", src / "train_tiny.toml", "--out", trained, "--no-progress")
    assert again.returncode == 0 and "training already complete (160 steps)" in again.stdout + again.stderr
    assert (trained / "final.pt").read_bytes() == before


def test_evaluate_runs_the_trained_weights(plugin, trained, tmp_path):
    src, env, _ = plugin
    data = tmp_path / "data"
    _ok(lfbench(env, "synth", "--out", data, "--seed", "100", "--size", "64", "--scenes", "1", "--no-progress"))
    spec = f"tinycnn:weights={trained / 'final.pt'}"
    _ok(lfbench(env, "evaluate", "--data", data, "--method", spec, "--out", tmp_path / "eval"))
    records = json.loads((tmp_path / "eval" / "results.json").read_text())["records"]
    mse = {r["scene"]: r["value"] for r in records if r["method"] == spec and r["metric"] == "mse_x100"}
    scene = Benchmark.discover(data).scenes[0]
    assert set(mse) == {scene.name}

    # Independent reference: the network rebuilt from final.pt by hand, scored inside the 15 px border.
    state = torch.load(trained / "final.pt", map_location="cpu", weights_only=True)
    net = _tiny_net(state["config"])
    net.load_state_dict(state["state_dict"])
    views = torch.from_numpy(scene.gray_views().reshape(1, 81, 64, 64).astype(np.float32))
    gt = scene.gt_disparity()[15:-15, 15:-15]
    with torch.no_grad():
        trained_pred = net.eval()(views)[0][0].numpy()[15:-15, 15:-15]
        torch.manual_seed(7)  # the config's seed: the weights training started from
        untrained_pred = _tiny_net(state["config"]).eval()(views)[0][0].numpy()[15:-15, 15:-15]
    reference = 100 * float(np.mean(np.square(gt - trained_pred, dtype=np.float32)))
    assert mse[scene.name] == pytest.approx(reference, rel=1e-4)
    assert np.abs(trained_pred - untrained_pred).max() > 0.05  # the trained weights are the ones used
    assert reference < 100 * float(np.mean(np.square(gt - untrained_pred)))  # and they predict better


def test_ablate_over_a_plugin_parameter(plugin, tmp_path):
    src, env, _ = plugin
    out = tmp_path / "ablate"
    _ok(lfbench(env, "ablate", src / "ablate_channels.toml", "--out", out, "--no-progress"))
    cells = pd.read_csv(out / "table_cells.csv").set_index("cell")
    assert list(cells.index) == ["channels=4", "channels=8"] and list(cells["channels"]) == [4, 8]
    budget = "ours (batch 4, patch 16, 20+5 steps, cpu)"  # no width: the network has none
    badpix, mse = f"BadPix 0.07 (%), {budget}", f"MSE x100, {budget}"
    for channels in (4, 8):
        cell = out / "cells" / f"channels={channels}"
        final = torch.load(cell / "final.pt", map_location="cpu", weights_only=True)
        assert final["method"] == "tinycnn" and final["config"]["channels"] == channels
        assert final["state_dict"]["body.0.weight"].shape == (channels, 81, 3, 3)
        marker = json.loads((cell / "cell.json").read_text())
        assert marker["values"] == {"channels": channels} and marker["steps"] == 25  # the budget's 20 + 5
        assert 0 <= cells.loc[f"channels={channels}", badpix] <= 100
        assert json.loads((cell / "timing.json").read_text())["test_s"] > 0
    # the cells differ, so each was trained with its own parameter
    assert cells.loc["channels=4", mse] != cells.loc["channels=8", mse]
    bad = src / "bad_axis.toml"
    bad.write_text((src / "ablate_channels.toml").read_text().replace("channels = [4, 8]", "width = [4, 8]"))
    proc = lfbench(env, "ablate", bad, "--out", tmp_path / "bad", "--list")
    assert proc.returncode == 2 and "grid[0].width: unknown axis; use channels, layers, d_min, d_max, interval, " \
                                   "angular, loss, beta, lr, seed" in proc.stderr


def test_bench_times_the_plugin_network(plugin, tmp_path):
    _, env, _ = plugin
    _ok(lfbench(env, "bench", "inference", "--model", "tinycnn", "--size", "16", "--precision", "fp32",
                "--threads", "1", "--json", tmp_path / "inference.json"))
    (rec,) = json.loads((tmp_path / "inference.json").read_text())
    assert rec["model"] == "tinycnn" and rec["channels"] == 8 and rec["disparities"] == 9 and rec["size"] == 16
    # TinyCNN.flops: 2 x (81*8 + 8*8 + 8*9) x 9 multiply-adds per pixel
    assert rec["tflop"] * 1e12 == pytest.approx(2 * 9 * (81 * 8 + 8 * 8 + 8 * 9) * 16 * 16)
    assert rec["gflops_per_s"] == pytest.approx(rec["tflop"] * 1e3 / rec["seconds"])
    _ok(lfbench(env, "bench", "train", "--model", "tinycnn:channels=4", "--batch", "1", "--patch", "16",
                "--steps", "1", "--threads", "1", "--json", tmp_path / "train.json"))
    (rec,) = json.loads((tmp_path / "train.json").read_text())
    assert rec["model"] == "tinycnn" and rec["channels"] == 4 and rec["steps_per_s"] > 0
    proc = lfbench(env, "bench", "inference", "--model", "tinycnn", "--width", "3")
    assert proc.returncode == 2 and "network 'tinycnn' has no parameter 'width'" in proc.stderr


def test_ddp_trains_the_plugin_network_in_two_processes(plugin, tmp_path):
    """torchrun with 2 CPU processes (gloo): both ranks end with the same parameters, the exported ones."""
    src, env, _ = plugin
    text = (src / "train_tiny.toml").read_text().replace("batch_size = 4", "batch_size = 2")
    text = text.replace("steps = 150", "steps = 3").replace("steps = 10", "steps = 2")
    config = tmp_path / "ddp.toml"
    config.write_text(text)
    out = tmp_path / "ddp"
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
                           "-m", "lfbench", "train", str(config), "--out", str(out), "--no-progress"],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    final = torch.load(out / "final.pt", map_location="cpu", weights_only=True)
    from lfbench.training.checkpoint import state_sha256

    names = [n for n, _ in _tiny_net(final["config"]).named_parameters()]
    digests = final["training"]["rank_parameters_sha256"]
    assert final["training"]["world_size"] == 2 and final["training"]["steps"] == 5
    assert len(digests) == 2 and digests[0] == digests[1] == state_sha256({n: final["state_dict"][n] for n in names})
