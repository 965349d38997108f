"""DDP training of the paper's compared networks (EPINET, DistgDisp, OACC-Net): two CPU processes under torchrun
(gloo), batch 2 = 1 per rank, end with bit-identical weights on both ranks, equal to one process that takes the
same batch as 2 micro-batches of 1 (BatchNorm sees the same 1-sample batches, so the averaged gradients agree
up to float rounding). OACC-Net's training pass receives the ground truth through DDP's forward as well.
(tests/test_training.py does the same for SubFocal on the HCI scenes.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import torch

REPO = Path(__file__).resolve().parents[1]


def _config(network: str, folder: Path, **training: object) -> Path:
    """The network's CPU smoke config, 2 steps, no validation, no augmentation, one thread, batch 2
    (+ ``training``)."""
    cfg = tomllib.loads((REPO / "configs" / f"{network}_cpu_smoke.toml").read_text(encoding="utf-8"))
    cfg["data"].pop("validation", None)
    cfg["data"]["synthetic"] = [s for s in cfg["data"]["synthetic"] if "val" not in s["category"]]
    cfg["data"]["random_gray"] = False  # no random draws besides the patches (each rank draws its own)
    cfg["augment"] = {"enabled": False}
    cfg["validation"] = {**cfg.get("validation", {}), "every": 0}
    cfg["training"] = {**cfg["training"], "batch_size": 2, "threads": 1, "checkpoint_every": 100, "log_every": 1,
                       **training}
    cfg["stages"] = [{"name": "l1", "loss": "l1", "lr": 1e-3, "steps": 2}]
    path = folder / f"{network}{'_acc' if training else ''}.toml"
    path.write_text(tomli_w.dumps(cfg), encoding="utf-8")
    return path


@pytest.mark.slow
@pytest.mark.parametrize("network", ["epinet", "distgdisp", "oaccnet"])
def test_two_process_ddp_matches_one_process(network, tmp_path):
    from lfbench.cli import main

    out = tmp_path / "ddp"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
                           "-m", "lfbench", "train", str(_config(network, tmp_path)), "--out", str(out),
                           "--no-progress"], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    # 1x1 weights in channels-last memory: their gradients get the weights' strides (no DDP copy, no warning)
    assert "Grad strides do not match" not in proc.stderr
    ddp = torch.load(out / "final.pt", map_location="cpu", weights_only=True)
    digests = ddp["training"]["rank_parameters_sha256"]
    assert ddp["training"]["world_size"] == 2 and len(digests) == 2 and digests[0] == digests[1]

    assert main(["train", str(_config(network, tmp_path, accumulate=2)), "--out", str(tmp_path / "one"),
                 "--no-progress"]) == 0
    one = torch.load(tmp_path / "one" / "final.pt", map_location="cpu", weights_only=True)
    # the parameters (BatchNorm's running statistics are buffers: each rank updates its own from its sample, one
    # process updates them once per micro-batch)
    from lfbench.method.trainable import get_trainable

    keys = [name for name, _ in get_trainable(network).build(**ddp["config"]).named_parameters()]
    assert keys and set(keys) <= set(ddp["state_dict"]) & set(one["state_dict"])
    for key in keys:
        torch.testing.assert_close(ddp["state_dict"][key], one["state_dict"][key], rtol=1e-4, atol=1e-6)
    # the logged losses (averaged over ranks) are the single process's, and the first step moved the weights
    losses = [[e["loss"] for e in map(json.loads, (folder / "metrics.jsonl").read_text().splitlines())
               if e["event"] == "train"] for folder in (out, tmp_path / "one")]
    assert len(losses[0]) == 2 and losses[0][0] != losses[0][1]
    np.testing.assert_allclose(losses[0], losses[1], rtol=1e-5)
