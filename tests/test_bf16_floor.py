"""benchmarks/bf16_floor.py (where the time of one inference goes against the conv peak) on a tiny network, so
that it cannot rot: its convolution clock must see every convolution of the fast path (its FLOPs add up to
the network's analytic count), and a CPU without bf16 skips the bf16 case in one line. No timing asserted."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(tmp_path: Path, args: list[str], **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bf16_floor.py"), *args], capture_output=True,
                          text=True, timeout=600, env={**os.environ, "OMP_NUM_THREADS": "1", **env}, cwd=tmp_path)


@pytest.mark.slow
def test_the_breakdown_accounts_for_every_convolution(tmp_path: Path):
    from lfbench_methods.subfocal.network import SubFocalNet

    from lfbench.utils.hardware import cpu_bf16_missing

    out = tmp_path / "floor.json"
    proc = _run(tmp_path, ["--size", "24", "--width", "4", "--interval", "1", "--precision", "fp32", "bf16",
                           "--repeat", "1", "--threads", "1", "--sweep", "--profile", "5", "--json", str(out),
                           "--table", str(tmp_path / "floor.md")])
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    records = json.loads(out.read_text())
    expected = ["fp32", "bf16"] if cpu_bf16_missing() is None else ["fp32"]
    assert [r["precision"] for r in records] == expected
    flops = SubFocalNet(width=4, interval=1.0).flops(24, 24)
    last = 2 * 27 * 4 * 9 * 24 * 24  # the 4 -> 1 last layer: a matrix product, not a convolution call
    for r in records:
        convs = r["convs"]
        # Every 2D convolution is the feature extractor, every 3D one the aggregation but its last layer.
        assert sum(c["gflop"] for c in convs if c["conv"].startswith("2d")) * 1e9 == pytest.approx(flops["extractor"])
        assert sum(c["gflop"] for c in convs if c["conv"].startswith("3d")) * 1e9 == pytest.approx(
            flops["aggregation"] - last)
        dtypes = {c["conv"].split()[-1] for c in convs if c["conv"].startswith("3d")}
        assert dtypes == {r["precision"]}  # the aggregation runs in the case's precision
        assert {c["conv"].split()[-1] for c in convs if c["conv"].startswith("2d")} == {"fp32"}  # features: fp32
        assert r["floor_s"] == pytest.approx(r["tflop"] * 1e3 / r["peaks_gflops_per_s"][r["precision"]])
        assert r["ratio_to_floor"] == pytest.approx(r["cpu_seconds"] / r["floor_s"])
        assert r["aggregation_conv_s"] == pytest.approx(sum(c["seconds"] for c in convs if c["conv"].startswith("3d")))
        assert [c["shape"] for c in r["sweep"]] == [[150, 150, 17, 64, 64], [4, 4, 9, 24, 24], [4, 4, 9, 24, 24],
                                                    [324, 4, 4, 24, 24]]
        assert "| self ms |" in r["profile"]
    assert "ratio to floor" in (tmp_path / "floor.md").read_text()


def test_bf16_on_a_cpu_without_it_is_one_line(tmp_path: Path):
    out = tmp_path / "floor.json"
    proc = _run(tmp_path, ["--size", "8", "--width", "2", "--interval", "1", "--precision", "bf16", "--repeat", "1",
                           "--json", str(out)], LFBENCH_FORCE_NO_BF16="1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stderr.strip().splitlines() == [
        "bf16 skipped: this CPU has no bf16 convolutions (it lacks avx512bw, avx512vl, avx512dq (simulated by "
        "LFBENCH_FORCE_NO_BF16=1))"]
    assert json.loads(out.read_text()) == []
