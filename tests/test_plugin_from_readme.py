"""The README's plugin section is enough on its own: the plugin it shows (a network that lfbench has never
seen, registered with @register_trainable only) is written from the README's own code blocks, installed
as the README says, and run with the README's own commands (train, evaluate, tiles, bench), each in a
fresh process. Then its results are checked against the network rebuilt by hand from the weights file."""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import code_blocks, install_package, isolate_registries, readme_section

from lfbench.data.hci import HCIDataset

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"

pytestmark = pytest.mark.slow


def _section() -> str:
    return readme_section("Plugins: your own network or method")


def _files(section: str) -> dict[str, str]:
    """The blocks whose first line is ``# file: PATH``: PATH -> text."""
    out = {}
    for _, body in code_blocks(section):
        first, _, rest = body.partition("\n")
        if first.startswith("# file: "):
            out[first.removeprefix("# file: ").strip()] = rest
    return out


def _commands(section: str) -> list[list[str]]:
    """The ``lfbench ...`` lines of the bash block that runs the README's plugin (comments stripped)."""
    block = next(body for lang, body in code_blocks(section) if lang == "bash" and "epistack" in body)
    return [shlex.split(line.split("  #")[0]) for line in block.splitlines() if line.startswith("lfbench ")]


@pytest.fixture(scope="module")
def readme_plugin(tmp_path_factory):
    """(source folder written from the README, environment with the plugin installed)."""
    section = _section()
    files = _files(section)
    assert set(files) == {"my_lfnet/plugin.py", "pyproject.toml", "train_epistack.toml"}, set(files)
    src = tmp_path_factory.mktemp("readme_plugin")
    for name, text in files.items():
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        (src / name).write_text(text, encoding="utf-8")
    (src / "my_lfnet" / "__init__.py").touch()  # as the README says
    site = tmp_path_factory.mktemp("readme_site")
    install_package(src, site)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(site), os.environ.get("PYTHONPATH")) if p),
           "OMP_NUM_THREADS": "1"}
    return src, env, _commands(section)


def _run(env: dict, cwd: Path, args: list[str]) -> str:
    proc = subprocess.run([sys.executable, "-m", *args], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, (args, proc.stderr[-2000:])
    return proc.stdout


def _lfbench_fails(env: dict, cwd: Path, args: list[str]) -> str:
    proc = subprocess.run([sys.executable, "-m", *args], env=env, cwd=cwd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 1, (args, proc.stdout, proc.stderr[-2000:])
    return proc.stdout


def test_the_readme_plugin_runs_with_the_readme_commands(readme_plugin):
    src, env, commands = readme_plugin
    assert [c[1] for c in commands] == ["methods", "train", "synth", "evaluate", "evaluate", "bench", "bench",
                                        "check-plugin"]
    outputs = [_run(env, src, [*c, "--no-progress"] if c[1] in ("train", "synth", "evaluate") else c)
               for c in commands]
    listing = outputs[0]
    assert "epistack: EPI streams through the centre row and column, a distribution over disparity bins." in listing
    assert "features (int [1, 256], default 8): channels of each EPI stream" in listing

    # trained: both stages ran, the distribution loss too, and the weights say which network they hold
    final = torch.load(src / "runs" / "epi" / "final.pt", map_location="cpu", weights_only=True)
    assert final["method"] == "epistack" and final["training"]["steps"] == 70
    log = [json.loads(line) for line in (src / "runs" / "epi" / "metrics.jsonl").read_text().splitlines()]
    assert [e["stage_name"] for e in log if e["event"] == "train"][-1] == "js"

    # evaluated: the records are the network's, rebuilt here by hand from the weights file
    saved = json.loads((src / "runs" / "epi" / "eval" / "results.json").read_text())
    (label,) = {r["method"] for r in saved["records"]}
    assert label.startswith("epistack:weights=sha256:")
    with pytest.MonkeyPatch.context() as mp:  # its registration is forgotten afterwards
        isolate_registries(mp)
        mp.syspath_prepend(str(src))
        from my_lfnet.plugin import EpiNet  # the README's own network
    sys.modules.pop("my_lfnet.plugin", None)
    sys.modules.pop("my_lfnet", None)
    net = EpiNet(**final["config"]).eval()
    net.load_state_dict(final["state_dict"])
    scene = HCIDataset.open(src / "data").scenes[0]
    views = torch.from_numpy(scene.gray_views().reshape(1, 81, 48, 48).astype(np.float32))
    with torch.inference_mode():
        pred = net(views)[0][0].numpy()
    gt = scene.gt_disparity()[15:-15, 15:-15]
    mse = {r["metric"]: r["value"] for r in saved["records"]}["mse_x100"]
    assert mse == pytest.approx(100 * float(np.mean(np.square(gt - pred[15:-15, 15:-15]))), rel=1e-4)
    # in exact tiles (its receptive radius): the same numbers up to float rounding
    tiled = json.loads((src / "runs" / "epi" / "tiled" / "results.json").read_text())
    assert {r["method"] for r in tiled["records"]} == {label + ",tile=16,device=cpu"}
    assert {r["metric"]: r["value"] for r in tiled["records"]}["mse_x100"] == pytest.approx(mse, rel=1e-5)

    # timed: its own parameter as a bench flag, one case per value; the training bench too
    bench_lines = [line for line in outputs[5].splitlines() if line.startswith("[inference]")]
    assert len(bench_lines) == 2 and "features 4" in bench_lines[0] and "features 8" in bench_lines[1]
    assert [line for line in outputs[6].splitlines() if line.startswith("[train]")]
    assert "path" not in outputs[6]

    # checked (issue 32.2): every contract the README states; no flops() declared; no weights, so no sign
    status = {line.split(":")[0].split()[1]: line.split()[0] for line in outputs[7].splitlines()[:-1]}
    assert status == {"build": "ok", "forward": "ok", "sign": "skip", "receptive_radius": "ok", "tiling": "ok",
                      "flops": "skip", "save/load": "ok", "training": "ok"}, outputs[7]
    assert "receptive_radius: 2 px" in outputs[7]
    # the 70 steps above teach it no disparity: the sign check says so instead of passing
    weights = _lfbench_fails(env, src, ["lfbench", "check-plugin", "epistack", "--weights", "runs/epi/final.pt"])
    assert "FAIL  sign: on planes at +1 and -1 px it predicts" in weights and "Train longer" in weights
