"""Unbounded reads and allocations (issue 20, classes 6 and 7): every file is read with a byte cap and only
as a regular file, headers are checked before data, TOML/JSON nesting and integers are bounded, and
what a run allocates from a flag, a grid or a checkpoint config is checked before it is allocated.
Each case answers with one line, exit 2, quickly (an alarm turns a hang into a failure)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, run_cli, write_scene, write_submission

from lfbench.utils.errors import DataError, SpecError

SIZE = 32  # px: 2 px scored inside the 15 px border (a border that leaves none is refused)
SECONDS = 30  # each bad input must be answered well within this


@pytest.fixture()
def deadline():
    """Fail (instead of hanging) when a command reads forever or blocks on a FIFO."""
    if not hasattr(signal, "SIGALRM"):
        pytest.skip("needs SIGALRM")

    def expire(signum, frame):
        raise TimeoutError(f"no answer within {SECONDS} s: the input was read without a bound")

    old = signal.signal(signal.SIGALRM, expire)
    signal.alarm(SECONDS)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


_LIMITED = textwrap.dedent("""
    import resource, sys
    resource.setrlimit(resource.RLIMIT_AS, (3 * 1024**3, 3 * 1024**3))  # an 8.6 GB read must not happen
    from lfbench.cli import main
    sys.exit(main(sys.argv[1:]))
""")


def _sparse_pfm(path: Path, side: int = 46341) -> Path:
    """A PFM whose header says side x side and whose size matches (a few KB on disk)."""
    header = f"Pf\n{side} {side}\n-1\n".encode()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        f.write(header)
        f.truncate(len(header) + side * side * 4)
    return path


def _run_limited(*argv, timeout: float = 120) -> subprocess.CompletedProcess:
    """``lfbench ARGV`` in a fresh process limited to 3 GiB of address space; a run past ``timeout`` s is
    returned as exit code 124 with the reason (not an exception)."""
    pytest.importorskip("resource")
    try:
        return subprocess.run([sys.executable, "-c", _LIMITED, *map(str, argv)], capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return subprocess.CompletedProcess(argv, 124, "", f"no answer within {timeout} s\n")


def _special(tmp: Path, name: str, kind: str) -> Path:
    """``tmp/name`` as a link to /dev/zero (a device: size 0, endless) or as a FIFO nobody writes to."""
    path = tmp / name
    if kind == "device":
        if not Path("/dev/zero").exists():
            pytest.skip("no /dev/zero")
        path.symlink_to("/dev/zero")
    else:
        if not hasattr(os, "mkfifo"):
            pytest.skip("no FIFOs here")
        os.mkfifo(path)
    return path


def _results(tmp: Path) -> Path:
    path = tmp / "results.json"
    path.write_text('[{"method": "m", "scene": "s", "metric": "mse_x100", "value": 1.0, "resolution": "lowres"}]')
    return path


def _golden(tmp: Path) -> Path:
    path = tmp / "golden.json"
    path.write_text('[{"method": "m", "scene": "s", "metric": "mse_x100", "value": 1.0, "tolerance": 0, '
                    '"resolution": "lowres"}]')
    return path


# (id, file name, argv given tmp and the special file)
READERS: list[tuple[str, str, Callable[[Path, Path], list]]] = [
    ("train-config", "c.toml", lambda t, f: ["-q", "train", f, "--out", t / "run"]),
    ("ablate-spec", "spec.toml", lambda t, f: ["ablate", f, "--out", t / "ab"]),
    ("regress-golden", "g.json", lambda t, f: ["regress", f, _results(t)]),
    ("regress-new", "r.json", lambda t, f: ["regress", _golden(t), f]),
    ("regress-update-new", "r.json", lambda t, f: ["regress", "--update", t / "g.json", f]),
    ("report-results", "r.json", lambda t, f: ["report", f, "--out", t / "rep"]),
    ("predict-npy", "v.npy", lambda t, f: ["predict", "--method", "constant", "--input", f, "--out", t / "o.pfm"]),
    ("convert-keras", "m.hdf5", lambda t, f: ["convert-keras", f, t / "o.pt"]),
    ("evaluate-weights", "w.pt", lambda t, f: ["evaluate", "--data", write_scene(t / "data", size=SIZE), "--method",
                                               f"subfocal:weights={f}", "--out", t / "out"]),
]


def _nothing_written(tmp: Path, special: Path) -> None:
    assert not [p for p in tmp.iterdir() if p != special and p.name in ("run", "ab", "rep", "o.pfm", "o.pt", "out",
                                                                        "g.json")]


@pytest.mark.parametrize(("name", "build"), [r[1:] for r in READERS], ids=[r[0] for r in READERS])
def test_a_fifo_as_input_is_one_line(tmp_path, capsys, deadline, name, build):
    """A FIFO nobody writes to blocked open() for ever."""
    special = _special(tmp_path, name, "fifo")
    rc, _, err = run_cli(capsys, *build(tmp_path, special))
    assert_one_error_line(rc, err, name, "not a regular file")
    _nothing_written(tmp_path, special)


@pytest.mark.parametrize(("name", "build"), [r[1:] for r in READERS], ids=[r[0] for r in READERS])
def test_a_device_as_input_is_one_line(tmp_path, name, build):
    """/dev/zero as a config or golden file read for ever (the size check trusted st_size, 0 for a device),
    filling memory: run in a process with a memory limit and a timeout, so that a regression fails here
    instead of taking the machine."""
    special = _special(tmp_path, name, "device")
    proc = _run_limited(*build(tmp_path, special), timeout=SECONDS)
    assert_one_error_line(proc.returncode, proc.stderr, name, "not a regular file")
    _nothing_written(tmp_path, special)


def test_the_byte_cap_does_not_trust_stat(tmp_path):
    from lfbench.utils.readfile import read_bytes, read_text

    proc = Path("/proc/self/maps")  # a regular file whose st_size is 0, holding kilobytes
    if proc.is_file() and proc.stat().st_size == 0:
        with pytest.raises(DataError, match="larger than 64 bytes, more than lfbench reads"):
            read_bytes(proc, "maps", 64)
    big = tmp_path / "big.toml"
    big.write_bytes(b"a = 1\n" * 1000)
    with pytest.raises(SpecError, match="big.toml: config is larger than 5999 bytes"):
        read_text(big, "config", 5999, error=SpecError)
    assert read_text(big, "config", 6000, error=SpecError).count("\n") == 1000


# --------------------------------------------------------------------------- sparse PFM headers

@pytest.mark.parametrize("which", ["ground truth", "published map"])
def test_a_sparse_pfm_is_refused_from_its_header(tmp_path, which):
    """A 46341x46341 PFM whose size matched was read whole before its shape was checked: MemoryError."""
    scene = write_scene(tmp_path / "data", "tiny", "training", size=SIZE)
    if which == "ground truth":
        bad = _sparse_pfm(scene / "gt_disp_lowres.pfm")
        method = "gt"
        expected = f"ground truth is 46341x46341, expected {SIZE}x{SIZE}"
    else:
        sub = write_submission(tmp_path / "sub", {"tiny": np.zeros((SIZE, SIZE), np.float32)})
        bad = _sparse_pfm(sub / "disp_maps" / "tiny.pfm")
        method = f"published:path={sub}"
        expected = f"prediction is 46341x46341, scene is {SIZE}x{SIZE}: larger than the scene"
    proc = _run_limited("evaluate", "--data", tmp_path / "data", "--method", method, "--out", tmp_path / "out",
                        "--no-progress")
    assert_one_error_line(proc.returncode, proc.stderr, str(bad), expected)
    assert not (tmp_path / "out").exists()


def test_pfm_headers_are_checked_before_the_data(tmp_path):
    from lfbench.data.pfm import MAX_PFM_PIXELS, read_pfm, write_pfm

    path = tmp_path / "m.pfm"
    write_pfm(path, np.zeros((4, 6), np.float32))
    assert read_pfm(path, shape=(4, 6)).shape == (4, 6) and read_pfm(path, max_shape=(4, 6)).shape == (4, 6)
    with pytest.raises(DataError, match="map is 6x4, expected 4x4"):
        read_pfm(path, shape=(4, 4))
    with pytest.raises(DataError, match=r"map is 6x4, scene is 5x5: larger than the scene"):
        read_pfm(path, max_shape=(5, 5))
    side = int(MAX_PFM_PIXELS**0.5) + 1
    with pytest.raises(DataError, match="more than lfbench reads"):
        read_pfm(_sparse_pfm(tmp_path / "big.pfm", side))


# --------------------------------------------------------------------------- TOML and JSON: nesting, integers

def _config(tmp: Path, top: str = "", extra: str = "") -> Path:
    root = write_scene(tmp / "data", size=SIZE).parent.parent
    path = tmp / "c.toml"
    path.write_text(f'{top}\n[data]\nroots = ["{root}"]\n[model]\nwidth = 2\n{extra}\n[[stages]]\nloss = "l1"\n'
                    'lr = 1e-3\nsteps = 1\n')
    return path


@pytest.mark.parametrize(("top", "extra", "fragment"), [
    ("seed = " + "9" * 400, "", "integer of 400 digits is outside TOML's 64-bit range"),
    ("seed = 18446744073709551616", "", "seed: integer of 20 digits is outside TOML's 64-bit range"),
    ("seed = " + "9" * 5000, "", "an integer with thousands of digits"),
    ("deep = " + "[" * 3000 + "]" * 3000, "", "nested more than 32 levels deep"),
    ("deep = " + "{a = " * 40 + "1" + "}" * 40, "", "nested more than 32 levels deep"),
    ("", "[training]\n" + "a." * 60 + "b = 1", "nested more than 32 levels deep"),
])
def test_hostile_toml_in_a_training_config_is_one_line(tmp_path, capsys, deadline, top, extra, fragment):
    """Deep nesting raised RecursionError; a 400-digit seed OverflowError; 5000 digits Python's int limit."""
    path = _config(tmp_path, top, extra)
    rc, _, err = run_cli(capsys, "-q", "train", path, "--out", tmp_path / "run")
    assert_one_error_line(rc, err, "c.toml", fragment)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(("text", "fragment"), [
    ('title = "x"\nseeds = [' + "9" * 400 + "]", "integer of 400 digits"),
    ('title = "x"\nnested = ' + "[" * 3000 + "]" * 3000, "nested more than 32 levels deep"),
])
def test_hostile_toml_in_an_ablation_spec_is_one_line(tmp_path, capsys, deadline, text, fragment):
    spec = tmp_path / "spec.toml"
    spec.write_text(text)
    rc, _, err = run_cli(capsys, "ablate", spec, "--out", tmp_path / "ab")
    assert_one_error_line(rc, err, "spec.toml", fragment)


@pytest.mark.parametrize(("text", "fragment"), [
    ('{"records": [], "meta": {"n": ' + "9" * 400 + "}}", "integer with 400 digits"),
    ('{"records": [], "meta": {"n": ' + "1" * 5000 + "}}", "integer with 5000 digits"),
    ('{"records": [], "meta": {"n": -9223372036854775809}}', "outside the 64-bit range"),
])
def test_huge_integers_in_a_results_file_are_one_line(tmp_path, capsys, text, fragment):
    path = tmp_path / "results.json"
    path.write_text(text)
    rc, _, err = run_cli(capsys, "report", path, "--out", tmp_path / "rep")
    assert_one_error_line(rc, err, "results.json", fragment)


def test_64_bit_integers_still_read(tmp_path):
    from lfbench.utils.jsonfile import parse_json
    from lfbench.utils.tomlfile import read_toml

    assert parse_json("[18446744073709551615, -9223372036854775808]") == [2**64 - 1, -(2**63)]
    assert json.loads("[1, 2.5]") == parse_json("[1, 2.5]")
    path = tmp_path / "c.toml"
    path.write_text("seed = 9223372036854775807\nlow = -9223372036854775808\n[a.b]\nc = [[1], {d = 2}]\n")
    assert read_toml(path, "config")[0] == {"seed": 2**63 - 1, "low": -(2**63), "a": {"b": {"c": [[1], {"d": 2}]}}}


# --------------------------------------------------------------------------- allocations from flags and specs

@pytest.mark.parametrize(("argv", "fragment"), [
    (["inference", "--size", str(10**6)], "--size: must be in [8, 4096], got 1000000"),
    (["train", "--batch", str(10**7)], "--batch: must be in [1, 4096], got 10000000"),
    (["train", "--patch", str(10**5)], "--patch: must be in [8, 1024], got 100000"),
    (["train", "--steps", "0"], "--steps: must be in [1, 1000000], got 0"),
    (["volume", "--size", "-5"], "--size: must be in [8, 4096], got -5"),
    (["inference", "--max-memory", "nan"], "--max-memory: must be a finite number, got nan"),
    (["metrics", "--scenes", str(10**9)], "--scenes: must be in [1, 1000], got 1000000000"),
])
def test_bench_sizes_are_bounded_when_parsed(tmp_path, capsys, argv, fragment):
    """bench --size 10**6, --batch 10**7, --patch 10**5 ran a case that died with exit 1 and no line."""
    rc, _, err = run_cli(capsys, "bench", *argv, "--json", tmp_path / "b.json")
    assert_one_error_line(rc, err, fragment)
    assert not (tmp_path / "b.json").exists()


def test_bench_refuses_a_network_its_trainable_refuses_before_any_case(tmp_path, capsys):
    rc, out, err = run_cli(capsys, "bench", "train", "--model", "subfocal:interval=0.0001", "--patch", "16",
                           "--json", tmp_path / "b.json")
    assert_one_error_line(rc, err, "--model subfocal:interval=0.0001", "disparities")
    assert "cases" not in out and not (tmp_path / "b.json").exists()


def test_an_ablation_grid_of_a_million_cells_is_refused_before_any_cell(tmp_path, capsys, deadline):
    """A 1000 x 1000 grid was still being expanded after 90 s."""
    config = _config(tmp_path)
    spec = tmp_path / "spec.toml"
    values = ", ".join(str(v) for v in range(1, 1001))
    spec.write_text(f'base = "{config}"\n[evaluation]\nsynthetic = {{ seed = 1, size = 32, scenes = 1 }}\n'
                    f'[[grid]]\n"training.log_every" = [{values}]\nseed = [{values}]\n')
    rc, _, err = run_cli(capsys, "ablate", spec, "--out", tmp_path / "ab")
    assert_one_error_line(rc, err, "spec.toml", "1000000 cells is more than one spec may run (1024)")
    assert not (tmp_path / "ab").exists()


@pytest.mark.parametrize(("evaluation", "fragment"), [
    ("time_size = 1000000000", "evaluation.time_size: must be in [16, 4096], got 1000000000"),
    ("time_repeats = 1000000000", "evaluation.time_repeats: must be in [1, 1000], got 1000000000"),
    ("synthetic = { seed = 1, size = 100000, scenes = 1 }", "evaluation.synthetic.size: must be in [32, 4096]"),
    ("synthetic = { seed = 1, size = 32, scenes = 100000000 }", "evaluation.synthetic.scenes: must be in [1, 1000]"),
])
def test_ablation_evaluation_sizes_are_bounded(tmp_path, capsys, evaluation, fragment):
    """A test-time light field of 10**9 px per side was only allocated after every cell had trained."""
    spec = tmp_path / "spec.toml"
    synthetic = "" if "synthetic" in evaluation else "synthetic = { seed = 1, size = 32, scenes = 1 }\n"
    spec.write_text(f'[evaluation]\n{synthetic}{evaluation}\n[[methods]]\nspec = "constant"\n')
    rc, _, err = run_cli(capsys, "ablate", spec, "--out", tmp_path / "ab")
    assert_one_error_line(rc, err, "spec.toml", fragment)
    assert not (tmp_path / "ab").exists()


# --------------------------------------------------------------------------- networks: any trainable

def _wide_trainable():
    import torch
    from torch import nn

    from lfbench.method.trainable import Trainable, register_trainable, trainable_registry

    class Wide(nn.Module):
        def __init__(self, channels: int = 8, angular: int = 9) -> None:
            super().__init__()
            self.angular = angular
            self.conv = nn.Conv2d(angular * angular, channels, 3, padding=1)
            self.head = nn.Conv2d(channels, 1, 3, padding=1)

        def forward(self, views):
            return self.head(torch.relu(self.conv(views)))[:, 0], None

    class WideTrainable(Trainable):
        """A plugin network that checks nothing itself.

        channels: hidden channels
        angular: views per row
        """

        network = Wide

    return register_trainable("wide", trainable_registry(None))(WideTrainable)()


def test_a_checkpoint_config_too_large_for_any_trainable_is_refused_before_building(tmp_path):
    """channels = 10**9 in a plugin checkpoint's config ended in an allocator traceback."""
    import torch

    from lfbench.training.checkpoint import export_weights

    trainable = _wide_trainable()
    path = tmp_path / "final.pt"
    export_weights(path, trainable.build(channels=4), method="wide", config={"channels": 10**9, "angular": 9})
    with pytest.raises(DataError) as info:
        trainable.load(path)
    message = str(info.value)
    assert str(path) in message and "more than lfbench builds (2 GiB)" in message and "\n" not in message
    good = tmp_path / "good.pt"
    export_weights(good, trainable.build(channels=4), method="wide", config={"channels": 4, "angular": 9})
    assert isinstance(trainable.load(good), torch.nn.Module)


def test_a_training_config_too_large_for_any_trainable_is_refused(tmp_path):
    from lfbench.method.trainable import MAX_NETWORK_BYTES, network_bytes

    trainable = _wide_trainable()
    with pytest.raises(ValueError, match="more than lfbench builds"):
        trainable.check_params({"channels": 10**9})
    trainable.check_params({"channels": 16})
    assert network_bytes(trainable.build, {"channels": 16}) == 4 * (81 * 16 * 9 + 16 + 16 * 9 + 1)
    assert network_bytes(trainable.build, {"channels": 10**9}) > MAX_NETWORK_BYTES
