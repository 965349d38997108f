"""lfbench bench inference timing several networks in one run (SubFocal's Table III runtime column): every
network at the same input with its own parameters, and each one's ratio to a reference network. The cases
are faked (no process, no timing): what is checked is which cases run and the arithmetic of the ratios."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lfbench.cli import main
from lfbench.cli.bench import _models_in
from lfbench.runs import bench

SECONDS = {"subfocal": 2.0, "lfattnet": 0.8, "epinet": 0.5}  # made-up times per network


@pytest.fixture()
def fake_cases(monkeypatch) -> list[tuple[str, dict]]:
    """run_isolated replaced: each case is recorded and answered with its network's made-up time."""
    ran: list[tuple[str, dict]] = []

    def fake(bench_: str, params: dict, timeout_s=None) -> dict:
        ran.append((bench_, dict(params)))
        return {"bench": bench_, **params, "seconds": SECONDS[params["model"]] * (2 if params.get("precision") ==
                                                                                  "bf16" else 1)}

    monkeypatch.setattr(bench, "run_isolated", fake)
    return ran


def test_models_are_read_from_every_model_flag():
    assert _models_in(["--size", "8"]) == ["subfocal"]
    assert _models_in(["--model", "a", "b:x=-1", "--size", "8", "--model=c"]) == ["a", "b:x=-1", "c"]
    assert _models_in(["--model", "a", "--model", "b"]) == ["a", "b"]


def test_several_networks_at_one_input_with_their_own_parameters_and_ratios(fake_cases, tmp_path: Path, capsys):
    out = tmp_path / "t3.json"
    code = main(["bench", "inference", "--model", "subfocal:width=3,interval=0.5", "lfattnet:d_min=-1,d_max=2",
                 "--model", "epinet:filters=2,depth=0", "--size", "24", "--repeat", "3", "--mean", "--precision",
                 "fp32", "bf16",
                 "--no-peak", "--device", "cpu", "--json", str(out)])
    assert code == 0
    assert [(p["model"], p["precision"]) for _, p in fake_cases] == [
        (m, p) for m in ("subfocal", "lfattnet", "epinet") for p in ("fp32", "bf16")]
    for _, p in fake_cases:  # the same input and statistic for all
        assert (p["size"], p["repeat"], p["statistic"]) == (24, 3, "mean")
    sub, att = fake_cases[0][1], fake_cases[2][1]
    assert (sub["width"], sub["interval"]) == (3, 0.5) and (att["d_min"], att["d_max"]) == (-1, 2)
    assert "width" not in att and "d_min" not in fake_cases[4][1]  # each only its own parameters
    records = json.loads(out.read_text())
    got = {(r["model_spec"], r["precision"]): r["ratio_to_reference"] for r in records}
    # Each precision divided by the reference's time at that precision: 0.8 / 2, 0.5 / 2 (bf16: 1.6 / 4, 1 / 4).
    assert got == {("subfocal:width=3,interval=0.5", "fp32"): 1.0, ("subfocal:width=3,interval=0.5", "bf16"): 1.0,
                   ("lfattnet:d_min=-1,d_max=2", "fp32"): 0.4, ("lfattnet:d_min=-1,d_max=2", "bf16"): 0.4,
                   ("epinet:filters=2,depth=0", "fp32"): 0.25, ("epinet:filters=2,depth=0", "bf16"): 0.25}
    assert {r["reference"] for r in records} == {"subfocal:width=3,interval=0.5"}
    text = capsys.readouterr().out
    row = next(line for line in text.splitlines() if line.startswith("| lfattnet") and "fp32" in line)
    assert "| 0.4 " in row and "| 0.8 " in row


def test_ratio_to_another_network_by_name(fake_cases, tmp_path: Path):
    out = tmp_path / "r.json"
    assert main(["bench", "inference", "--model", "subfocal", "epinet:filters=2,depth=0", "--ratio-to", "epinet",
                 "--size", "24", "--precision", "fp32", "--no-peak", "--device", "cpu", "--json", str(out)]) == 0
    assert [r["ratio_to_reference"] for r in json.loads(out.read_text())] == [4.0, 1.0]


def test_one_network_is_as_before_no_ratio(fake_cases, tmp_path: Path, capsys):
    out = tmp_path / "one.json"
    assert main(["bench", "inference", "--model", "subfocal", "--width", "3", "4", "--size", "16", "--precision",
                 "fp32", "--no-peak", "--device", "cpu", "--json", str(out)]) == 0
    records = json.loads(out.read_text())
    assert [r["width"] for r in records] == [3, 4]  # the network's own flags, one case each
    assert not any("ratio_to_reference" in r or "model_spec" in r for r in records)
    assert "model_spec" not in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["--model", "subfocal", "epinet", "--ratio-to", "lfattnet"], "--ratio-to lfattnet: not one of the networks"),
    (["--model", "subfocal", "nosuch"], "nosuch"),
    (["--model", "subfocal", "epinet", "--width", "3"], "unrecognized arguments: --width 3"),
])
def test_bad_networks_are_one_line_and_exit_2_before_any_case(fake_cases, argv, message, capsys):
    try:
        code = main(["bench", "inference", *argv, "--size", "24", "--precision", "fp32", "--no-peak"])
    except SystemExit as exc:  # argparse's usage error
        code = exc.code
    assert code == 2 and message in capsys.readouterr().err and not fake_cases


def test_attach_ratios_matches_size_precision_and_device():
    recs = [{"bench": "inference", "model_spec": "a", "size": 8, "precision": "fp32", "device": "cpu", "seconds": 2.0},
            {"bench": "inference", "model_spec": "b", "size": 8, "precision": "fp32", "device": "cpu", "seconds": 3.0},
            {"bench": "inference", "model_spec": "b", "size": 16, "precision": "fp32", "device": "cpu", "seconds": 1.0},
            {"bench": "inference", "model_spec": "c", "size": 8, "precision": "fp32", "device": "cpu",
             "error": "exit 1"}]
    out = bench.attach_ratios(recs, "a")
    assert [r.get("ratio_to_reference") for r in out] == [1.0, 1.5, None, None]  # no reference at size 16
    assert "ratio_to_reference" not in recs[1]  # inputs unchanged


def test_the_forward_check_fits_a_network_of_valid_convolutions():
    """EPINET loses 11 px per side: the bench's check of its forward pass (16 px by default) used to refuse it."""
    from lfbench.method.trainable import get_trainable

    epinet = get_trainable("epinet")
    net = epinet.build(filters=2)  # the paper's 7 merged blocks
    assert epinet.output_margin(net) == 11
    epinet.check_forward(net)  # a 23 x 23 light field: no ValueError
