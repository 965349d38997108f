"""The bench plumbing (lfbench bench): records, machine info, isolation, peaks, tables. No timing assertions."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import pytest

from lfbench.cli import main
from lfbench.runs import bench
from lfbench.utils.errors import SpecError
from lfbench.utils.hardware import FORCE_NO_BF16_ENV, cpu_bf16_missing

CONTRACT = {"size", "interval", "precision", "seconds", "peak_memory_gb", "gflops_per_s"}


@pytest.mark.slow
def test_inference_command_writes_the_contract_records(tmp_path: Path, capsys):
    out = tmp_path / "OUT.json"
    # A tiny network on a tiny scene, in its own process, after the conv peak (in another process).
    code = main(["bench", "inference", "--size", "12", "--interval", "1", "--precision", "fp32", "bf16",
                 "--width", "3", "--threads", "1", "--device", "cpu", "--json", str(out)])
    assert code == 0  # a bf16 case this CPU cannot run is skipped, not an error
    records = json.loads(out.read_text())
    assert [r["precision"] for r in records] == ["fp32", "bf16"]  # only inference records in this file
    missing = cpu_bf16_missing()
    ran = records if missing is None else records[:1]
    if missing is not None:
        assert "avx512" in records[1]["skipped"] and "seconds" not in records[1]
    for r in ran:
        assert CONTRACT <= set(r)
        assert r["size"] == 12 and r["interval"] == 1.0 and r["width"] == 3 and r["disparities"] == 9
        assert r["seconds"] > 0 and r["gflops_per_s"] > 0 and r["device"] == "cpu" and r["memory"] == "rss"
        assert r["peak_memory_gb"] >= r["baseline_memory_gb"] > 0.05  # a fresh process with torch loaded
        assert r["tiles"] == 1 and r["tile"] == [12, 12] and r["weights"] == "random"
        assert set(r["phases_s"]) == {"features_s", "attention_s", "aggregation_s"}
        m = r["machine"]
        assert m["cores"] >= 1 and m["threads"] == 1 and m["torch"] and m["cpu"]
        # The measured peak sits beside the record, and the floor follows from the network's FLOPs.
        assert r["peak_gflops_per_s"] > 0
        assert r["fraction_of_peak"] == pytest.approx(r["gflops_per_s"] / r["peak_gflops_per_s"])
        assert r["fraction_of_peak_cpu"] > 0 and r["cpu_seconds"] > 0
        assert r["floor_s"] == pytest.approx(r["tflop"] * 1e3 / r["peak_gflops_per_s"])
        # Both floors beside each record, whatever precision it ran in (bf16: where this CPU has it).
        assert r["ratio_to_fp32_floor"] == pytest.approx(r["seconds"] / r["fp32_floor_s"])
        assert r["ratio_to_fp32_floor_cpu"] > 0 and set(r["phases_cpu_s"]) == set(r["phases_s"])
        if missing is None:
            assert r["ratio_to_bf16_floor"] == pytest.approx(r["seconds"] / r["bf16_floor_s"])
            assert r[f"ratio_to_{r['precision']}_floor"] == pytest.approx(r["ratio_to_floor"])
        else:
            assert "avx512" in r["bf16_floor_skipped"] and "ratio_to_bf16_floor" not in r
    text = capsys.readouterr().out
    assert "## inference" in text and "## peak" in text and "machine:" in text


def test_bf16_on_a_cpu_without_it_is_skipped_with_its_reason(tmp_path: Path, capsys, monkeypatch):
    monkeypatch.setenv(FORCE_NO_BF16_ENV, "1")  # as on an AVX2-only CPU
    out = tmp_path / "OUT.json"
    code = main(["bench", "inference", "--size", "12", "--interval", "1", "--precision", "bf16", "fp32",
                 "--width", "3", "--threads", "1", "--no-peak", "--json", str(out)])
    assert code == 0
    bf16, fp32 = json.loads(out.read_text())
    assert bf16["precision"] == "bf16" and "seconds" not in bf16
    assert bf16["skipped"].startswith("this CPU has no bf16 convolutions (it lacks avx512bw, avx512vl, avx512dq")
    assert fp32["precision"] == "fp32" and fp32["seconds"] > 0 and "skipped" not in fp32
    text = capsys.readouterr().out
    assert "[inference] bf16 skipped: this CPU has no bf16 convolutions" in text
    assert "skipped: this CPU has no bf16" in text.split("## inference")[1]
    assert bench.skip_reason("peak", {"precision": "bf16"})
    assert bench.skip_reason("volume", {"precision": "bf16"}) is None  # a gather, no convolution


@pytest.mark.skipif(__import__("torch").cuda.is_available(), reason="this machine has CUDA")
def test_a_cuda_device_without_cuda_is_one_line_and_exit_2(capsys):
    assert main(["bench", "peak", "--device", "cuda", "--precision", "fp32"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "device=cuda" in err[0] and "sees no CUDA GPU" in err[0]


def test_network_flops_are_the_analytic_count():
    from lfbench_methods.subfocal.network import SubFocalNet

    f = SubFocalNet().flops(512, 512)
    # The issue's ~44 TFLOP: 17 disparities x 512^2 px x 2 x 27 x (324*150 + 6*150^2 + 150).
    assert f["aggregation"] == 17 * 512 * 512 * 2 * 27 * (324 * 150 + 6 * 150 ** 2 + 150)
    assert f["aggregation"] == pytest.approx(44.2e12, rel=1e-3)
    # Extractor per view pixel (multiply-adds): stem 180, layer1 576, layer2 4*8 + 288 + 15*576,
    # layer3 128 + 1152 + 3*2304, layer4 256 + 4*2304, last 5760 + 64; SPP 64 per pooled pixel.
    per_px = 180 + 576 + (32 + 288 + 15 * 576) + (128 + 1152 + 3 * 2304) + (256 + 4 * 2304) + 5824
    pooled = sum((512 // p) ** 2 for p in (2, 4, 8, 16)) * 64
    assert f["extractor"] == 2 * 81 * (per_px * 512 * 512 + pooled)
    assert f["total"] == pytest.approx(f["extractor"] + f["aggregation"] + f["attention"])
    assert SubFocalNet(interval=0.1).flops(512, 512)["aggregation"] == pytest.approx(f["aggregation"] * 81 / 17)


def _parse(argv: list[str]):
    import argparse

    from lfbench.cli.bench import add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(argv)


def test_every_inference_case_sits_between_the_peaks_of_the_precisions_asked(monkeypatch):
    from lfbench.cli.bench import _cases

    both = _parse(["inference", "--size", "12", "--precision", "fp32", "bf16", "--interval", "1", "--device", "cpu"])
    monkeypatch.delenv(FORCE_NO_BF16_ENV, raising=False)
    if cpu_bf16_missing() is None:
        order = [(bench_, params.get("precision")) for bench_, params in _cases(both)]
        peaks = [("peak", "fp32"), ("peak", "bf16")]
        assert order == [*peaks, ("inference", "fp32"), *peaks, ("inference", "bf16"), *peaks]
    # Only the precisions asked for are measured: --precision fp32 runs no bf16 peak at all (on a CPU
    # without bf16 it used to try one anyway, and the run exited 1).
    fp32 = _parse(["inference", "--size", "12", "--precision", "fp32", "--interval", "1", "0.5", "--device", "cpu"])
    order = [(bench_, params.get("precision"), params.get("interval")) for bench_, params in _cases(fp32)]
    assert order == [("peak", "fp32", None), ("inference", "fp32", 1.0), ("peak", "fp32", None),
                     ("inference", "fp32", 0.5), ("peak", "fp32", None)]
    # A CPU without bf16: its bf16 peak is one skipped case (one line), not one around every case.
    monkeypatch.setenv(FORCE_NO_BF16_ENV, "1")
    cases = _cases(both)
    order = [(bench_, params.get("precision")) for bench_, params in cases]
    assert order == [("peak", "fp32"), ("peak", "bf16"), ("inference", "fp32"), ("peak", "fp32"),
                     ("inference", "bf16"), ("peak", "fp32")]
    record = bench.run_isolated(*cases[1])  # decided here, no process
    assert record["skipped"].startswith("this CPU has no bf16 convolutions (it lacks avx512bw")
    assert _parse(["inference", "--no-peak"]).no_peak and all(b == "inference" for b, _ in _cases(
        _parse(["inference", "--no-peak", "--device", "cpu"])))


def test_attach_peaks_and_the_table():
    peak = {"bench": "peak", "precision": "bf16", "seconds": 1.0, "shape": [150, 17, 64, 64]}
    records = [{**peak, "gflops_per_s": 300.0, "gflops_per_cpu_s": 200.0},
               {"bench": "inference", "size": 512, "interval": 0.5, "precision": "bf16", "seconds": 200.0,
                "gflops_per_s": 200.0, "gflops_per_cpu_s": 100.0, "tflop": 40.0, "peak_memory_gb": 3.5,
                "machine": {"load_average": 2.5}},
               {**peak, "gflops_per_s": 500.0, "gflops_per_cpu_s": 200.0},
               {"bench": "inference", "size": 512, "interval": 0.5, "precision": "fp32", "seconds": 1.0,
                "gflops_per_s": 1.0, "tflop": 1.0, "peak_memory_gb": 1.0}]
    out = bench.attach_peaks(records)
    # The peak is the mean of the measurements just before and after the case: (300 + 500) / 2.
    assert out[1]["peak_gflops_per_s"] == 400.0 and out[1]["fraction_of_peak"] == 0.5
    assert out[1]["fraction_of_peak_cpu"] == 0.5  # 100 / 200 GFLOP per CPU second
    assert out[1]["floor_s"] == 100.0 and out[1]["ratio_to_floor"] == 2.0  # 40 TFLOP at 400 GFLOP/s
    assert "fraction_of_peak" not in out[3]  # no fp32 peak measured
    assert "ratio_to_floor" not in records[1]  # inputs are not modified
    text = bench.table(out)
    assert "## peak" in text and "## inference" in text
    row = next(line for line in text.splitlines() if line.startswith("| 512") and "bf16" in line)
    assert "| 2.5 " in row and "| 0.5 " in row  # load average and fraction of peak in the row


def test_both_floors_beside_every_inference_record():
    def peak(precision: str, gflops: float) -> dict:
        return {"bench": "peak", "precision": precision, "gflops_per_s": gflops, "gflops_per_cpu_s": gflops}

    def case(precision: str, seconds: float) -> dict:
        return {"bench": "inference", "size": 64, "precision": precision, "seconds": seconds, "tflop": 2.0,
                "gflops_per_s": 2000 / seconds}

    records = [peak("fp32", 100.0), peak("bf16", 300.0), case("fp32", 30.0), peak("fp32", 300.0),
               peak("bf16", 500.0), case("bf16", 10.0), peak("fp32", 200.0), peak("bf16", 200.0)]
    fp32, bf16 = bench.attach_peaks(records)[2], bench.attach_peaks(records)[5]
    # fp32 case: peaks (100 + 300) / 2 = 200 (fp32) and (300 + 500) / 2 = 400 (bf16) GFLOP/s around it.
    assert fp32["fp32_floor_s"] == 10.0 and fp32["ratio_to_fp32_floor"] == 3.0
    assert fp32["bf16_floor_s"] == 5.0 and fp32["ratio_to_bf16_floor"] == 6.0
    assert fp32["ratio_to_floor"] == 3.0  # its own precision's floor
    # bf16 case: fp32 peak (300 + 200) / 2 = 250, bf16 peak (500 + 200) / 2 = 350.
    assert bf16["fp32_floor_s"] == 8.0 and bf16["ratio_to_fp32_floor"] == 1.25
    assert bf16["bf16_floor_s"] == pytest.approx(2000 / 350) and bf16["ratio_to_bf16_floor"] == pytest.approx(1.75)
    assert bf16["ratio_to_floor"] == pytest.approx(1.75)
    # By CPU seconds: 5 CPU s for 2 TFLOP at the peaks' 250 / 350 GFLOP per CPU second.
    bf16_cpu = bench.attach_peaks([*records[:5], {**records[5], "cpu_seconds": 5.0}, *records[6:]])[5]
    assert bf16_cpu["ratio_to_fp32_floor_cpu"] == pytest.approx(0.625)
    assert bf16_cpu["ratio_to_bf16_floor_cpu"] == pytest.approx(0.875)
    assert "ratio_to_bf16_floor_cpu" not in bf16  # no CPU time, no CPU ratio
    rows = _table_rows(bench.table(bench.attach_peaks(records)), "size")
    assert rows[1]["precision"] == "bf16"
    assert {k: rows[1][k] for k in ("ratio_to_fp32_floor", "bf16_floor_s", "ratio_to_bf16_floor")} == {
        "ratio_to_fp32_floor": "1.25", "bf16_floor_s": "5.71", "ratio_to_bf16_floor": "1.75"}
    # Without bf16 units: the bf16 peak is a skipped record, and so is the ratio to its floor.
    reason = "this CPU has no bf16 convolutions (it lacks avx512bw, avx512vl, avx512dq); fp32 runs"
    no_bf16 = [peak("fp32", 100.0), {"bench": "peak", "precision": "bf16", "skipped": reason}, case("fp32", 30.0),
               peak("fp32", 100.0)]
    r = bench.attach_peaks(no_bf16)[2]
    assert r["ratio_to_fp32_floor"] == 1.5 and r["bf16_floor_skipped"] == reason and "bf16_floor_s" not in r
    row = _table_rows(bench.table([r]), "size")[0]
    assert (row["ratio_to_fp32_floor"], row["bf16_floor_s"], row["ratio_to_bf16_floor"]) == ("1.5", "", "skipped")
    assert row["ratio_to_bf16_floor_cpu"] == "skipped"


def _table_rows(text: str, first: str) -> list[dict]:
    """The rows (column -> cell) of the Markdown table in ``text`` whose first column is ``first``."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {first} "))
    table = itertools.takewhile(lambda line: line.startswith("|"), lines[start:])
    cells = [[c.strip() for c in line.strip().strip("|").split("|")] for line in table]
    return [dict(zip(cells[0], row, strict=True)) for row in cells[2:]]


def test_metrics_bench_scores_every_scene_and_method():
    r = bench.run_case("metrics", {"scenes": 2, "methods": 3, "size": 40})
    assert r["bench"] == "metrics" and r["scenes"] == 2 and r["methods"] == 3 and r["metrics"] == 5
    assert r["scores_per_s"] == pytest.approx(6 / r["seconds"])
    assert r["machine"]["cpu"] and "load_average_before" in r["machine"]


def test_volume_bench_measures_both_paths_in_process():
    from lfbench_methods.subfocal.bench import bench_volume

    for method in ("gather", "grid_sample"):
        r = bench_volume(size=10, interval=1.0, precision="bf16", method=method, threads=1)
        item = 2 if method == "gather" else 4  # grid_sample is the fp32 reference path
        assert r["volume_gb"] == pytest.approx(9 * 10 * 10 * 324 * item / 1e9)
        assert r["gb_per_s"] == pytest.approx(r["volume_gb"] / r["seconds"])


@pytest.mark.slow
def test_a_failing_case_is_a_record_with_an_error_and_exit_code_1(tmp_path: Path, capsys):
    r = bench.run_isolated("peak", {"precision": "fp16"})
    assert "error" in r and "fp16" in r["error"]
    assert main(["bench", "volume", "--size", "8", "--interval", "0.3", "--method", "gather",
                 "--precision", "fp32", "--json", str(tmp_path / "v.json")]) == 1  # 8 / 0.3 is not a grid
    assert "error" in json.loads((tmp_path / "v.json").read_text())[0]
    assert "error" in capsys.readouterr().out


def test_memory_helpers():
    assert bench.peak_rss_gb() > 0
    assert 0 < bench.current_rss_gb() <= bench.peak_rss_gb() * 1.01
    info = bench.machine_info()
    assert {"cpu", "cores", "threads", "torch", "load_average"} <= set(info)


def test_train_bench_interleaves_the_reference_and_fast_paths():
    import argparse

    from lfbench.cli.bench import _cases, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["train", "--width", "16", "--batch", "4", "--path", "reference", "fast", "--rounds", "2",
                              "--precision", "fp32", "bf16"])
    cases = _cases(args)
    assert [(c[0], c[1]["path"], c[1]["precision"], c[1]["width"], c[1]["batch"]) for c in cases] == [
        ("train", "reference", "fp32", 16, 4), ("train", "reference", "bf16", 16, 4),
        ("train", "fast", "fp32", 16, 4), ("train", "fast", "bf16", 16, 4)] * 2
    r = bench.bench_train(width=2, batch=1, patch=8, steps=1, threads=1, path="reference")
    assert r["path"] == "reference" and r["steps_per_s"] == pytest.approx(1 / r["seconds_per_step"])
    assert 0 < r["cpu_seconds"]


def test_a_network_s_train_bench_options_are_declared_flags(capsys):
    import argparse

    from lfbench.cli.bench import add_arguments
    from lfbench.method.trainable import bench_options, get_trainable
    from lfbench.utils.options import Param

    path = {o.name: o for o in bench_options(get_trainable("subfocal").train_bench_options)}["path"]
    assert isinstance(path, Param) and path.choices == ("fast", "reference") and path.default == ("fast",)
    parser = argparse.ArgumentParser(prog="lfbench bench")
    add_arguments(parser)
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(["train", "--path", "fast", "bogus"])
    assert exc.value.code == 2
    assert "argument --path: expected one of 'fast', 'reference', got 'bogus'" in capsys.readouterr().err
    with pytest.raises(SpecError, match="network 'subfocal': weight_grad: expected one of 'auto', 'gemm', "
                                        "'native', got 'fastest'"):
        bench.bench_train(width=2, batch=1, patch=8, steps=1, threads=1, weight_grad="fastest")


def test_train_bench_compares_weight_gradients_on_the_fast_path_only(monkeypatch):
    import argparse

    from lfbench_methods.subfocal import weight_grad as wg

    from lfbench.cli.bench import _cases, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["train", "--width", "16", "--path", "reference", "fast",
                              "--weight-grad", "native", "gemm"])
    assert [(c[1]["path"], c[1].get("weight_grad")) for c in _cases(args)] == [
        ("reference", None), ("fast", "native"), ("fast", "gemm")]
    used = []
    real = wg.conv_with_gemm_weight_grad
    monkeypatch.setattr(wg, "conv_with_gemm_weight_grad", lambda x, w, d: used.append(w) or real(x, w, d))
    r = bench.bench_train(width=2, batch=1, patch=8, steps=1, threads=1, weight_grad="gemm")
    assert r["weight_grad"] == "gemm" and used  # the matrix-product gradients ran
    used.clear()
    r = bench.bench_train(width=2, batch=1, patch=8, steps=1, threads=1, weight_grad="native")
    assert r["weight_grad"] == "native" and not used
    with pytest.raises(SpecError, match="weight_grad applies to the fast training path"):
        bench.bench_train(width=2, batch=1, patch=8, steps=1, threads=1, path="reference", weight_grad="gemm")


def test_the_metrics_bench_scores_every_pair_of_its_synthetic_hci_scenes(monkeypatch):
    """`lfbench bench metrics` scores scenes it writes in HCI's layout (it once opened them through the generic
    scene contract, which has no ground truth of its own, and failed): every (scene, method) pair is scored."""
    from lfbench.runs import bench as bench_module
    from lfbench.scoring import score as score_module

    calls = []
    real = score_module.score_scene

    def counting(scene, pred, metrics):
        out = real(scene, pred, metrics)
        calls.append((scene.name, out))
        return out

    monkeypatch.setattr(score_module, "score_scene", counting)
    record = bench_module.bench_metrics(scenes=2, methods=3, size=32)
    assert len(calls) == 6 and {name for name, _ in calls} == {"scene_00", "scene_01"}
    assert record["size"] == 32 and record["scenes"] == 2 and record["methods"] == 3
    # the predictions are the ground truth plus noise of 0.02 px per method rank: MSE x100 grows with the rank
    first = [out for name, out in calls if name == "scene_00"]
    mse = [o.values["mse_x100"] for o in first]
    assert mse[0] < mse[1] < mse[2]


def test_suite_out_keeps_the_run_named_after_the_date_and_the_machine(tmp_path: Path, capsys):
    """`lfbench bench suite --out DIR` writes the records and the table as DIR/<date>-<host>[-quick].json and
    .md (what benchmarks/suite.py did before it was folded into the command)."""
    import platform

    code = main(["bench", "suite", "--quick", "--skip", "peak", "inference", "volume", "train",
                 "--out", str(tmp_path / "kept")])
    assert code == 0
    files = sorted(p.name for p in (tmp_path / "kept").iterdir())
    stem = files[0].removesuffix(".json")
    assert files == [f"{stem}.json", f"{stem}.md"] and stem.endswith(f"-{platform.node() or 'host'}-quick")
    records = json.loads((tmp_path / "kept" / f"{stem}.json").read_text(encoding="utf-8"))
    assert [r["bench"] for r in records] == ["metrics"]
