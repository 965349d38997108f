"""benchmarks/gpu_check.py in its CPU mode (--device cpu --quick), so that the GPU check cannot rot: every
section runs and its numbers are the ones the CPU must give (identical paths, exact tiling, bit-identical
resume after a SIGKILL)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_gpu_check_runs_on_the_cpu(tmp_path: Path):
    from lfbench.utils.hardware import cpu_bf16_missing

    out = tmp_path / "check.json"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "gpu_check.py"), "--device", "cpu", "--quick",
                           "--json", str(out)], capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    report = json.loads(out.read_text())
    assert report["device"] == "cpu" and report["quick"] and report["fp32"] == "ieee"
    s = report["sections"]
    assert set(s) == {"inference", "gpu_vs_cpu", "tiled_vs_whole", "phase", "training", "ddp"}
    cases = {(c["interval"], c["precision"]): c for c in s["inference"]["cases"]}
    assert set(cases) == {(i, p) for i in (1.0, 0.5) for p in ("fp32", "bf16")}
    for (_, precision), c in cases.items():
        if precision == "bf16" and cpu_bf16_missing() is not None:
            assert "lacks" in c["skipped"]
        else:
            assert c["seconds"] > 0 and c["memory_gb"] > 0 and c["finite"]
    assert s["gpu_vs_cpu"]["max_abs_diff_px"] == 0.0  # the same CPU path twice
    assert s["tiled_vs_whole"]["tiles"] == 9 and s["tiled_vs_whole"]["max_abs_diff_px"] < 1e-4  # exact tiling
    assert s["phase"]["finite"] and s["phase"]["forward_max_abs_diff"] == s["phase"]["backward_max_abs_diff"] == 0.0
    t = s["training"]
    assert t["kill_exit"] == -9 and t["killed_at_step"] == 3 and t["resumed"] and t["resumed_steps"] == 4
    assert t["resumed_vs_uninterrupted_max_abs_diff"] == 0.0  # resume is bit-identical on the CPU
    assert t["steps_per_s"] > 0 and t["config"] == "configs/subfocal_paper.toml"
    assert s["ddp"] == {"skipped": "needs 2 CUDA GPUs", "section_s": 0.0}
    assert report["targets"] == {"note": "targets apply to a CUDA GPU"}


def test_gpu_check_on_a_missing_gpu_is_one_line(tmp_path: Path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "gpu_check.py"), "--json",
                           str(tmp_path / "x.json")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "sees no CUDA GPU" in proc.stderr
    assert not (tmp_path / "x.json").exists()


@pytest.mark.slow
def test_gpu_profile_runs_on_the_cpu(tmp_path: Path):
    from lfbench.utils.hardware import cpu_bf16_missing

    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "gpu_profile.py"), "--device", "cpu", "--quick",
                           "--out", str(tmp_path), "--budget", "1e6"],
                          capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    report = json.loads((tmp_path / "gpu_profile.json").read_text())
    assert report["device"] == "cpu" and report["quick"]
    assert [(c["width"], c["batch"]) for c in report["train"]] == [(4, 2), (4, 1)]
    assert all(c["steps_per_s"] > 0 for c in report["train"])
    table = (tmp_path / "profile_w4_b2.txt").read_text()
    assert "convolution_backward" in table  # the profiled step ran forward and backward
    for c in report["inference"]:
        if c["precision"] == "bf16" and cpu_bf16_missing() is not None:
            assert "lacks" in c["skipped"]
        else:
            assert c["seconds"] > 0
    assert {(c["width"], c["size"], c["precision"]) for c in report["inference"]} == {
        (w, 32, p) for w in (16, 4) for p in ("fp32", "bf16")}
