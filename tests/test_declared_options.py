"""One declared-option system (issue 29.3): TOML keys, method and network parameters and the command-line flags
several commands share are declared with the same types and bounds and checked by one function, in one
wording; every command that takes a shared flag has its one ceiling; docs/command-line.md is generated from
the flags' declarations."""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import Annotated, Literal

import pytest
import torch
from helpers import assert_one_error_line, isolate_registries, run_cli

from lfbench import Range
from lfbench.cli import argtypes, build_parser
from lfbench.method.trainable import Trainable, register_trainable
from lfbench.training.config import TrainConfig
from lfbench.utils.errors import SpecError
from lfbench.utils.flags import FLAGS, JOBS, MAX_JOBS, SEED, THREADS
from lfbench.utils.options import Bounds, Param, Table, parse_section

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "command-line.md"

#: What each command needs besides the flag to parse (nothing is run: only parsed).
REQUIRED = {"evaluate": ["--data", "d", "--method", "gt", "--out", "o"], "ablate": ["spec.toml"],
            "predict": ["--method", "gt", "--input", "v.npy", "--out", "o.pfm"], "synth": ["--out", "o"],
            "check-plugin": ["base"]}


def _cases() -> list[tuple[object, tuple[str, ...], float, str]]:
    """(flag, command, a value at a bound, a value past it) for every bound of every declared flag, for every
    command that takes it."""
    out = []
    for flag, commands in argtypes.flag_users().items():
        if flag.range is None:
            continue
        for command in commands:
            for bound, is_open, step in ((flag.range.low, flag.range.low_open, -1),
                                         (flag.range.high, flag.range.high_open, 1)):
                if bound is None:
                    continue
                inside = bound if not is_open else bound - step  # an open end: the nearest inside value
                outside = bound + step if not is_open else bound
                out.append(pytest.param(flag, command, inside, outside, id=f"{' '.join(command)}-{flag.flag}-{bound}"))
    return out


def _parse(command: tuple[str, ...], flag, value) -> argparse.Namespace:
    argv = [*command, *REQUIRED.get(command[0], []), flag.flag, str(value)]
    return build_parser(argv).parse_args(argv)


@pytest.mark.parametrize(("flag", "command", "inside", "outside"), _cases())
def test_every_command_taking_a_shared_flag_has_its_one_ceiling(capsys, flag, command, inside, outside):
    """Each command accepts the declared bound and refuses one past it: one usage line naming the flag, exit 2.
    (`ablate --jobs` took up to 1024 and `evaluate --jobs` 256; the seeds of synth, demo and check-plugin
    took anything argparse's int did, -1 included.)"""
    value = int(inside) if flag.kind is int else inside
    assert getattr(_parse(command, flag, value), flag.name) == value
    with pytest.raises(SystemExit) as exc:
        _parse(command, flag, int(outside) if flag.kind is int else outside)
    err = capsys.readouterr().err
    assert exc.value.code == 2
    line = assert_one_error_line(2, err, f"argument {flag.flag}: must be", flag.range.within())
    assert line.startswith(f"lfbench {' '.join(command)}: error:")


def test_jobs_is_shared_by_evaluate_and_ablate_with_one_ceiling():
    users = argtypes.flag_users()
    assert users[JOBS] == [("evaluate",), ("ablate",)] and JOBS.range.high == MAX_JOBS == 256
    assert [("synth",), ("check-plugin",)] == [c for c in users[SEED] if c[0] in ("synth", "check-plugin")]
    # --threads of lfbench bench is the threads parameter of every network's method: one declaration
    from lfbench.method.network_method import RUNTIME_PARAMS

    assert RUNTIME_PARAMS["threads"] is THREADS


def test_a_library_call_checks_jobs_by_the_same_declaration():
    """run_ablation and the scoring (evaluate, score_scenes) are public API: their guard is the flag's own check."""
    from lfbench.runs.runner import evaluate, score_scenes

    calls = (lambda jobs: score_scenes([], jobs=jobs, on_done=print), lambda jobs: evaluate([], [], jobs=jobs))

    for bad, problem in ((0, "must be in [1, 256], got 0"), (MAX_JOBS + 1, "got 257"), (True, "expected int, got bool"),
                         (2.0, "expected int, got float")):
        for call in calls:
            with pytest.raises(SpecError) as exc:
                call(bad)
            assert str(exc.value).startswith("--jobs: ") and str(exc.value).endswith(problem)


def test_a_parameter_and_a_toml_key_are_worded_alike():
    """A network parameter's bound and type messages are the TOML keys' (it said "must be 1 to 8" and
    "expects int, got str '16'" where a TOML key says "must be in [1, 8]" and "expected int, got str")."""
    from lfbench.utils.options import option

    @dataclasses.dataclass(frozen=True)
    class Section:
        width: int = option(2, low=1, high=8, help="a width")

    def toml(value) -> str:
        with pytest.raises(SpecError) as exc:
            parse_section(Section, Table({"width": value}, "net", None))
        return str(exc.value).split("net.width: ", 1)[1]

    param = Param("width", int, 2, "a width", Range(1, 8))
    for value in (9, 0, "16", 2.5, math.nan):
        assert param.problem(value) == toml(value)
    assert toml(9) == "must be in [1, 8], got 9" and toml("16") == "expected int, got str"
    assert dataclasses.astuple(Range(1, 8)) == dataclasses.astuple(Bounds(1, 8)) and Range(1, 8).text() == "[1, 8]"


class Narrow(torch.nn.Module):
    def __init__(self, width: Annotated[int, "channels", Range(1, 8)] = 2, angular: int = 9) -> None:
        super().__init__()
        self.angular = angular
        self.conv = torch.nn.Conv2d(angular * angular, 1, 3, padding=1)

    def forward(self, views):
        return self.conv(views)[:, 0], None


class NarrowNet(Trainable):
    """A plugin network whose width is bounded by Range(1, 8)."""

    network = Narrow


def test_a_plugin_range_refuses_the_same_value_from_a_spec_and_from_a_model_table(monkeypatch, capsys):
    """`Annotated[int, "help", Range(1, 8)]` (the plugin API) refuses 9 from a spec string and from a training
    config's [model] table with the same message, as a TOML key of the same bounds would."""
    isolate_registries(monkeypatch)
    register_trainable("narrow")(NarrowNet)
    rc, _, err = run_cli(capsys, "check-plugin", "narrow:width=9")
    assert assert_one_error_line(rc, err).endswith("narrow:width: must be in [1, 8], got 9")
    with pytest.raises(SpecError) as exc:
        TrainConfig.from_dict({"method": "narrow", "model": {"width": 9}, "stages": [{"loss": "l1", "steps": 1}],
                               "data": {"synthetic": [{"category": "synthetic"}]}})
    assert str(exc.value) == "model.width: must be in [1, 8], got 9"
    assert "width (int [1, 8], default 2): channels" in run_cli(capsys, "info", "narrow")[1]


def test_the_committed_flag_reference_is_what_the_declarations_generate(capsys):
    text = DOC.read_text(encoding="utf-8")
    assert argtypes.COMMAND in text.splitlines()[0]
    assert text == argtypes.reference(), f"{DOC.name} is stale: run `{argtypes.COMMAND}`"
    for flag in FLAGS:
        assert f"| `{flag.flag} {flag.metavar}` |" in text
    assert "docs/command-line.md" in (REPO / "README.md").read_text(encoding="utf-8")


# --------------------------------------------------------------------------- one declaration: sections

def _all_cli_flags() -> dict[str, list[argparse.Action]]:
    """Every command's (and every bench's) flags that were added from a declaration, by flag."""
    parser = build_parser()
    found: dict[str, list[argparse.Action]] = {}
    for _, sub in argtypes._parsers(parser):
        for action in sub._actions:
            declared = getattr(action, "declared", None)
            if declared is not None:
                found.setdefault(declared.flag, []).append(declared)
    return found


def test_every_declared_flag_is_an_option_of_a_section():
    """A command-line flag is not a second kind of declaration: each one lfbench's parsers add (shared, a
    command's own, a cluster option) is an option of a section, with the same type, default, bounds, help and
    metavar as there (a network's bench options are added when --model names it: BenchOption)."""
    from lfbench.cli.bench import BenchFlags
    from lfbench.cli.evaluate import EvaluateFlags
    from lfbench.cli.synth import SynthWorkers
    from lfbench.data.synth import SynthFlags
    from lfbench.utils.executor import ClusterOptions
    from lfbench.utils.flags import SharedFlags, section_flags
    from lfbench.utils.options import option_fields

    sections = (SharedFlags, ClusterOptions, BenchFlags, EvaluateFlags, SynthWorkers, SynthFlags)
    declared = {}
    for cls in sections:
        for f, opt, kind in option_fields(cls):
            declared.setdefault(f.name, []).append((kind, f.default, opt))
        assert set(section_flags(cls)) == {f.name for f, _, _ in option_fields(cls)}
    seen = _all_cli_flags()
    assert {"--jobs", "--gpus-per-job", "--partition", "--size", "--ci-block", "--workers", "--angular"} <= set(seen)
    for name, flags in seen.items():
        for flag in flags:
            assert flag.name in declared, name
            assert any(kind == flag.kind and default == flag.default and opt.help == flag.help
                       and (opt.bounds.text() or None) == (flag.range.text() if flag.range else None)
                       and opt.metavar == flag.metavar
                       for kind, default, opt in declared[flag.name]), name


@pytest.mark.parametrize(("given", "message"), [
    ({"gpus_per_job": -1}, "--gpus-per-job: must be >= 0, got -1"),
    ({"timeout_min": 0}, "--timeout-min: must be >= 1, got 0"),
    ({"cpus_per_job": True}, "--cpus-per-job: expected int, got bool"),
    ({"partition": 3}, "--partition: expected str, got int"),
    ({"max_parallel": 2.0}, "--max-parallel: expected int, got float"),
])
def test_cluster_options_from_python_are_checked_by_their_declaration(given, message):
    from lfbench.utils.executor import ClusterOptions

    with pytest.raises(SpecError) as err:
        ClusterOptions("pool", **given)
    assert str(err.value) == message
    assert ClusterOptions("pool", **{k: 1 if k != "partition" else "gpu" for k in given})  # in bounds: accepted


def test_ablate_reads_the_cluster_flags_into_the_section_they_declare(capsys):
    """What ``lfbench ablate --gpus-per-job`` etc. parse is what ClusterOptions receives, by the same names; a
    value out of the declared bounds is one usage line (exit 2) before any work."""
    from lfbench.utils.executor import ClusterOptions
    from lfbench.utils.flags import section_flags

    args = build_parser().parse_args(["ablate", "spec.toml", "--executor", "slurm", "--gpus-per-job", "2",
                                      "--cpus-per-job", "3", "--timeout-min", "7", "--partition", "p100",
                                      "--max-parallel", "4"])
    options = ClusterOptions(**{name: getattr(args, name) for name in section_flags(ClusterOptions)})
    assert options == ClusterOptions("slurm", gpus_per_job=2, cpus_per_job=3, timeout_min=7, partition="p100",
                                     max_parallel=4)
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["ablate", "spec.toml", "--timeout-min", "0"])
    assert exit_.value.code == 2
    assert "argument --timeout-min: must be >= 1, got 0" in capsys.readouterr().err


def test_a_network_s_train_bench_options_are_a_section_of_declared_options():
    """A network's ``lfbench bench train`` options are declared as every option is (a section; issue 38): the
    flags made from it take one or more of the Literal's choices, default to the declared values (None: unset)
    and refuse another value in the one wording."""
    from lfbench.method.trainable import bench_options
    from lfbench.utils.options import option

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Variants:
        mode: tuple[Literal["a", "b"], ...] = option(("a",), help="the mode(s)")
        kernel: tuple[Literal["x", "y", "z"] | None, ...] = option((None,), help="the kernel(s)", metavar="K")

    mode, kernel = bench_options(Variants)
    assert (mode.name, mode.choices, mode.default, mode.metavar, mode.help) == ("mode", ("a", "b"), ("a",), "{a,b}",
                                                                                "the mode(s)")
    assert (kernel.choices, kernel.default, kernel.metavar) == (("x", "y", "z"), (None,), "K")
    assert kernel.parse("y") == "y"
    assert kernel.problem("w") == "expected one of 'x', 'y', 'z', got 'w'"
    assert bench_options(None) == ()
