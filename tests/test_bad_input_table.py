"""Every command's promise for bad input (README): exit 2, exactly one line on stderr that names the
file or option, no traceback, and no output left behind. Table-driven: add a row for a new command or
flag; a hypothesis test feeds random bytes to the file readers behind the commands."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, run_cli, write_scene, write_submission
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lfbench.cli import BUILTIN_COMMANDS
from lfbench.data.pfm import write_pfm

SIZE = 32  # px: 2 px scored inside the 15 px border (a border that leaves none is refused)


def _scene(tmp: Path) -> Path:
    return write_scene(tmp / "data", "tiny", "training", size=SIZE)


def _file(tmp: Path, name: str, content: bytes | str) -> Path:
    path = tmp / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    return path


def _hdf5(tmp: Path, build: Callable) -> Path:
    h5py = pytest.importorskip("h5py")
    path = tmp / "model.hdf5"
    with h5py.File(path, "w") as f:
        build(f, h5py)
    return path


def _external_link(f, h5py) -> None:
    g = f.create_group("model_weights")
    g.attrs["layer_names"] = [b"conv3d"]
    g["conv3d"] = h5py.ExternalLink("/etc/passwd", "/")


def _soft_link(f, h5py) -> None:
    g = f.create_group("model_weights")
    g.attrs["layer_names"] = [b"conv3d"]
    g["conv3d"] = h5py.SoftLink("/nowhere")


def _dataset_as_layer(f, h5py) -> None:
    g = f.create_group("model_weights")
    g.attrs["layer_names"] = [b"conv3d"]
    g["conv3d"] = np.zeros(3)


def _text_weights(f, h5py) -> None:
    g = f.create_group("model_weights")
    g.attrs["layer_names"] = [b"conv3d"]
    g.create_group("conv3d/conv3d")["kernel:0"] = np.array([b"TOPSECRET"])


def _train_config(tmp: Path, extra: str) -> Path:
    root = _scene(tmp).parent.parent
    return _file(tmp, "c.toml", f'[data]\nroots = ["{root}"]\n[model]\nwidth = 2\n{extra}')


def _odd_submission(tmp: Path) -> Path:
    """A submission whose map is 3 px narrower than its scene (predict wrote it as it was, exit 0)."""
    return write_submission(tmp / "sub", {"tiny": np.zeros((SIZE, SIZE - 3), np.float32)})


def _wide_ci(tmp: Path) -> Path:
    """A results folder whose ci.csv has 3 rows of 100,000 columns (it took report --html over a minute)."""
    folder = _file(tmp, "res/results.json", RESULTS).parent
    row = ",".join(["m", "s", "mse_x100", "1", "0.5", "1.5", "10", "lowres"] + [""] * 99_992)
    _file(tmp, "res/ci.csv", "method,scene,metric,value,low,high,n_pixels,resolution\n" + f"{row}\n" * 3)
    return folder


def _fifo(tmp: Path, name: str) -> Path:
    path = tmp / name
    path.parent.mkdir(parents=True, exist_ok=True)
    os.mkfifo(path)
    return path


def _sparse(tmp: Path, name: str, size: int = 50 * 1024**3) -> Path:
    """A sparse file of ``size`` bytes behind a zip header (no disk used)."""
    path = tmp / name
    with open(path, "wb") as f:
        f.write(b"PK\x03\x04")
        f.truncate(size)
    return path


VICTIM = "victim"  # a folder beside OUT that a hostile output folder points at: it must stay as it was
ABLATION_SPEC = ('title = "t"\n[base.data]\ntrain = ["synthetic"]\n[[base.data.synthetic]]\ncategory = "synthetic"\n'
                 'seed = 1\nsize = 48\nscenes = 1\n[base.model]\nwidth = 2\n[[base.stages]]\nname = "l1"\n'
                 'loss = "l1"\nlr = 1e-3\nsteps = 1\n[evaluation]\nsynthetic = { seed = 5, size = 48, scenes = 1 }\n'
                 '[[grid]]\ninterval = [1.0]\n')
RESULTS = '{"records": [{"method": "m", "scene": "s", "metric": "mse_x100", "value": 1.0, "resolution": "lowres"}]}'


def _hostile(tmp: Path, name: str = "out") -> Path:
    """An output folder whose commit journal names a folder beside it as its staging folder (the next run
    would have deleted it)."""
    victim = tmp / VICTIM
    victim.mkdir(exist_ok=True)
    (victim / "keep.txt").write_text("mine")
    return _file(tmp, f"{name}/.lfbench-commit.json",
                 json.dumps({"stage": str(victim), "entries": [], "remove": []})).parent


def _cut(tmp: Path) -> Path:
    """A results folder whose commit was cut short (its journal pending)."""
    folder = _file(tmp, "res/results.json", RESULTS).parent
    (folder / ".lfbench-stage.1.planted").mkdir()
    _file(folder, ".lfbench-commit.json", json.dumps({"stage": ".lfbench-stage.1.planted", "entries": [],
                                                      "remove": []}))
    return folder


def _maps_leading_out(tmp: Path) -> Path:
    """A results folder whose saved maps of method 'm' are a link to a folder outside it."""
    folder = _file(tmp, "res/results.json", RESULTS).parent
    write_submission(tmp / "elsewhere", {"s": np.zeros((SIZE, SIZE), np.float32)})
    (folder / "maps").mkdir()
    (folder / "maps" / "m").symlink_to(tmp / "elsewhere")
    return folder


# (id, argv builder given tmp_path, fragments of the one error line, paths that must not exist afterwards)
CASES: list[tuple[str, Callable[[Path], list], tuple[str, ...], tuple[str, ...]]] = [
    ("evaluate-no-data", lambda t: ["evaluate", "--data", t / "nope", "--method", "gt", "--out", t / "out"],
     ("nope", "data root not found"), ("out",)),
    ("evaluate-bad-spec", lambda t: ["evaluate", "--data", _scene(t), "--method", "planesweep:interval=x", "--out",
                                     t / "out"], ("planesweep",), ("out",)),
    ("evaluate-constant-inf", lambda t: ["evaluate", "--data", _scene(t), "--method", "constant:value=inf", "--out",
                                         t / "out"], ("constant:value: must be a finite number, got inf",), ("out",)),
    ("evaluate-unknown-method", lambda t: ["evaluate", "--data", _scene(t), "--method", "nosuch", "--out", t / "out"],
     ("nosuch",), ("out",)),
    ("evaluate-ci-block-0", lambda t: ["evaluate", "--data", _scene(t), "--method", "gt", "--out", t / "out", "--ci",
                                       "--ci-block", "0"], ("--ci-block: must be in [1, 4096], got 0",), ("out",)),
    ("evaluate-ci-resamples-neg", lambda t: ["evaluate", "--data", _scene(t), "--method", "gt", "--out", t / "out",
                                             "--ci", "--ci-resamples", "-3"], ("--ci-resamples",), ("out",)),
    ("evaluate-out-is-file", lambda t: ["evaluate", "--data", _scene(t), "--method", "gt", "--out",
                                        _file(t, "out", "x")], ("out", "output folder is a file"), ()),
    ("evaluate-scene-unknown", lambda t: ["evaluate", "--data", _scene(t), "--scenes", "nosuch", "--method", "gt",
                                          "--out", t / "out"], ("no scene 'nosuch'",), ("out",)),
    ("predict-out-is-folder", lambda t: ["predict", "--method", "gt", "--input", _scene(t), "--out",
                                         _file(t, "o.pfm/x", "").parent], ("o.pfm", "is a folder"), ()),
    ("predict-bad-suffix", lambda t: ["predict", "--method", "gt", "--input", _scene(t), "--out", t / "o.png"],
     ("output must end in .pfm or .npy",), ("o.png",)),
    ("predict-npy-object", lambda t: ["predict", "--method", "gt", "--input", _file(t, "v.npy", b"\x93NUMPY\x01\x00"
                                      + b"v\x00{'descr': '|O', 'fortran_order': False, 'shape': (2,), }"
                                      + b" " * 57 + b"\n"), "--out", t / "o.pfm"], ("v.npy",), ("o.pfm",)),
    ("predict-garbage-params", lambda t: ["predict", "--method", "planesweep", "--input",
                                          _file(t, "s/parameters.cfg", "\x00\x01garbage").parent, "--out",
                                          t / "o.pfm"], ("parameters.cfg",), ("o.pfm",)),
    ("predict-published-odd-crop", lambda t: ["predict", "--method", f"published:path={_odd_submission(t)}",
                                              "--input", _scene(t), "--out", t / "o.pfm"],
     ("published:sub on tiny", f"prediction is {SIZE - 3}x{SIZE}, scene is {SIZE}x{SIZE}"), ("o.pfm",)),
    ("report-ci-csv-too-wide", lambda t: ["report", _wide_ci(t), "--out", t / "rep", "--html"],
     ("ci.csv", "a line of 100000 comma-separated fields"), ("rep",)),
    ("info-unknown", lambda t: ["info", "nosuch"], ("nosuch",), ()),
    ("regress-golden-nan", lambda t: ["regress", _file(t, "g.json", '[{"method": "m", "scene": "s", "metric": '
                                      '"mse_x100", "value": NaN, "tolerance": 0, "resolution": "lowres"}]'),
                                      _file(t, "r.json", "[]")], ("g.json", "NaN"), ()),
    ("regress-update-negative", lambda t: ["regress", "--update", "--tolerance", "-5", t / "g.json",
                                           _file(t, "r.json", "[]")], ("--tolerance",), ("g.json",)),
    ("regress-new-not-utf8", lambda t: ["regress", t / "g.json", _file(t, "r.json", b"\xff\xfe[")],
     ("r.json", "not UTF-8"), ()),
    ("report-deep-json", lambda t: ["report", _file(t, "r.json", "[" * 50000 + "]" * 50000), "--out", t / "rep"],
     ("r.json", "nested"), ("rep",)),
    ("report-runs-malformed", lambda t: ["report", _file(t, "r.json", '{"records": [], "runs": [7]}'), "--out",
                                         t / "rep"], ("r.json", "run 0 is malformed"), ("rep",)),
    ("evaluate-dataset", lambda t: ["evaluate", "--data", t, "--dataset", "nope", "--method", "gt", "--out", t / "o"],
     ("Unknown dataset 'nope'",), ("o",)),
    ("synth-layout-size", lambda t: ["synth", "--out", t / "s", "--layout", "urbanlf-syn", "--size", "64x200000"],
     ("size: must be in [16, 4096], got 200000",), ("s",)),
    ("synth-size", lambda t: ["synth", "--out", t / "s", "--size", "200000"], ("size: must be in [16, 4096]",),
     ("s",)),
    ("synth-scenes", lambda t: ["synth", "--out", t / "s", "--scenes", "100000000"], ("--scenes: must be in [1,",),
     ("s",)),
    ("demo-size", lambda t: ["demo", "--out", t / "d", "--size", "8"],
     ("argument --size: must be in [16, 4096], got 8",), ("d",)),
    ("synth-angular", lambda t: ["synth", "--out", t / "s", "--angular", "99"],
     ("argument --angular: must be in [3, 33], got 99",), ("s",)),
    ("synth-angular-even", lambda t: ["synth", "--out", t / "s", "--angular", "4"], ("angular: must be odd",), ("s",)),
    ("validate-size", lambda t: ["validate-submission", write_submission(t / "sub", {}), "--size", "60000"],
     ("--size",), ()),
    ("validate-missing", lambda t: ["validate-submission", t / "nope.zip"], ("nope.zip", "not found"), ()),
    ("convert-keras-external-link", lambda t: ["convert-keras", _hdf5(t, _external_link), t / "o.pt"],
     ("model.hdf5", "external link"), ("o.pt",)),
    ("convert-keras-soft-link", lambda t: ["convert-keras", _hdf5(t, _soft_link), t / "o.pt"],
     ("model.hdf5", "soft link"), ("o.pt",)),
    ("convert-keras-dataset-layer", lambda t: ["convert-keras", _hdf5(t, _dataset_as_layer), t / "o.pt"],
     ("model.hdf5", "not an HDF5 group"), ("o.pt",)),
    ("convert-keras-text-weights", lambda t: ["convert-keras", _hdf5(t, _text_weights), t / "o.pt"],
     ("model.hdf5", "not numbers"), ("o.pt",)),
    ("convert-keras-not-hdf5", lambda t: ["convert-keras", _file(t, "x.hdf5", "TOPSECRET"), t / "o.pt"],
     ("x.hdf5", "not an HDF5 file"), ("o.pt",)),
    ("train-no-stages", lambda t: ["-q", "train", _train_config(t, ""), "--out", t / "run"], ("c.toml", "stages"),
     ("run",)),
    ("train-beta", lambda t: ["-q", "train", _train_config(t, '[[stages]]\nloss = "uafl"\nbeta = "x"\nlr = 1e-3\n'
                                                              'steps = 1\n'), "--out", t / "run"],
     ("c.toml", "beta"), ("run",)),
    ("train-missing", lambda t: ["-q", "train", t / "nope.toml", "--out", t / "run"], ("nope.toml",), ("run",)),
    ("ablate-missing", lambda t: ["ablate", t / "nope.toml", "--out", t / "ab"], ("nope.toml",), ("ab",)),
    ("ablate-jobs-0", lambda t: ["ablate", t / "nope.toml", "--jobs", "0"], ("--jobs",), ()),
    ("bench-bad-model", lambda t: ["bench", "--model", "nosuch", "--json", t / "b.json"], ("nosuch",), ("b.json",)),
    ("check-plugin-unknown", lambda t: ["check-plugin", "nosuchnet"], ("nosuchnet",), ()),
    ("check-plugin-bad-param", lambda t: ["check-plugin", "subfocal:width=0"], ("width",), ()),
    ("check-plugin-no-weights", lambda t: ["check-plugin", "subfocal", "--weights", t / "nope.pt"],
     ("nope.pt", "not found"), ()),
    ("check-dataset-missing", lambda t: ["check-dataset", t / "nope"], ("nope", "data root not found"), ()),
    ("check-dataset-unknown", lambda t: ["check-dataset", _scene(t).parent.parent, "--dataset", "nosuchset"],
     ("nosuchset",), ()),
    ("check-dataset-bad-toml", lambda t: ["check-dataset", _file(t, "d/lfbench-dataset.toml",
                                                                 '[views]\npattern = "v{k}.png"\nangular = 3\n'
                                                                 'reverse_rows = 1\n').parent],
     ("lfbench-dataset.toml", "views.reverse_rows: expected bool, got int"), ()),
    ("new-plugin-bad-name", lambda t: ["new-plugin", "Bad Name", "--out", t / "p"], ("plugin name 'Bad Name'",),
     ("p",)),
    ("new-plugin-taken", lambda t: ["new-plugin", "subfocal", "--out", t / "p"], ("registered already",), ("p",)),
    # a write target that is not a regular file (issue 31; every command: test_write_targets.py)
    ("regress-update-fifo", lambda t: ["regress", "--update", _fifo(t, "g.json"), _file(t, "r.json", RESULTS)],
     ("g.json", "is a FIFO, not a regular file"), ()),
    ("predict-out-fifo", lambda t: ["predict", "--method", "gt", "--input", _scene(t), "--out", _fifo(t, "o.pfm")],
     ("o.pfm", "is a FIFO"), ()),
    ("bench-json-fifo", lambda t: ["bench", "inference", "--size", "16", "--json", _fifo(t, "b.json")],
     ("b.json", "is a FIFO"), ()),
    ("evaluate-out-holds-fifo", lambda t: ["evaluate", "--data", _scene(t), "--method", "gt", "--out",
                                           _fifo(t, "out/results.json").parent], ("results.json", "is a FIFO"),
     ("out/results.csv",)),
    # one spelling per metric id (issue 31): another spelling of a threshold is an unknown metric, not MISSING
    ("regress-golden-metric-spelling", lambda t: ["regress", _file(t, "g.json", '[{"method": "m", "scene": "s", '
                                                  '"metric": "badpix_0.0700", "value": 1, "tolerance": 0, '
                                                  '"resolution": "lowres"}]'), _file(t, "r.json", RESULTS)],
     ("g.json", "unknown metric 'badpix_0.0700'"), ()),
    ("predict-weights-huge", lambda t: ["predict", "--method", f"subfocal:weights={_sparse(t, 'w.pt')}", "--input",
                                        _scene(t), "--out", t / "o.pfm"], ("w.pt", "larger than the 8 GiB"),
     ("o.pfm",)),
    # hostile output folders (issue 20.1): every command that reads one or writes a set into one
    ("evaluate-hostile-out", lambda t: ["evaluate", "--data", _scene(t), "--method", "gt", "--out", _hostile(t)],
     (".lfbench-commit.json", "nothing was changed"), ()),
    ("evaluate-html-hostile-out", lambda t: ["evaluate", "--data", _scene(t), "--method", "gt", "--html", "--out",
                                             _hostile(t)], (".lfbench-commit.json", "nothing was changed"), ()),
    ("demo-hostile-out", lambda t: ["demo", "--out", _hostile(t), "--size", "32", "--scenes", "1", "--methods", "gt"],
     (".lfbench-commit.json", "nothing was changed"), ("out/data",)),
    ("report-hostile-out", lambda t: ["report", _file(t, "r.json", RESULTS), "--out", _hostile(t), "--html"],
     (".lfbench-commit.json", "nothing was changed"), ("out/html",)),
    ("report-cut-results", lambda t: ["report", _cut(t), "--out", t / "rep"], ("res", "interrupted run"), ("rep",)),
    ("report-maps-leading-out", lambda t: ["report", _maps_leading_out(t), "--out", t / "rep", "--html"],
     ("maps/m", "symbolic link leading out of"), ("rep",)),
    ("report-into-its-results", lambda t: ["report", _file(t, "res/results.json", RESULTS), "--out", t / "res"],
     ("res", "folder of the results being reported"), ("res/table_average.md",)),
    ("regress-cut-results", lambda t: ["regress", _file(t, "g.json", "[]"), _cut(t)], ("res", "interrupted run"), ()),
    ("ablate-hostile-out", lambda t: ["ablate", _file(t, "a.toml", ABLATION_SPEC), "--out", _hostile(t)],
     (".lfbench-commit.json", "nothing was changed"), ("out/eval_data", "out/cells")),
    ("ablate-report-only-hostile-out", lambda t: ["ablate", _file(t, "a.toml", ABLATION_SPEC), "--out", _hostile(t),
                                                  "--report-only", "--html"],
     (".lfbench-commit.json", "nothing was changed"), ("out/html",)),
    ("train-hostile-out", lambda t: ["-q", "train", _train_config(t, '[[stages]]\nloss = "l1"\nlr = 1e-3\nsteps = 1\n'),
                                     "--out", _hostile(t, "run")], (".lfbench-commit.json", "nothing was changed"),
     ("run/final.pt", "run/metrics.jsonl")),
]


def test_every_command_has_a_row():
    """A new command must add its bad-input rows here (``methods`` and ``datasets`` take no input)."""
    covered = {case[0].split("-")[0] for case in CASES}
    expected = {name.split("-")[0] for name in BUILTIN_COMMANDS if name not in ("methods", "datasets")}
    assert expected <= covered, sorted(expected - covered)


@pytest.mark.parametrize(("build", "fragments", "absent"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_exit_2_nothing_written(tmp_path, capsys, build, fragments, absent):
    argv = build(tmp_path)
    rc, out, err = run_cli(capsys, *argv)
    line = assert_one_error_line(rc, err, *fragments)
    assert "TOPSECRET" not in err and "root:" not in err  # never echo file content
    assert line.startswith("lfbench ")
    for name in absent:
        assert not (tmp_path / name).exists(), f"{name} was written"
    if (tmp_path / VICTIM).exists():  # what a hostile output folder pointed at is untouched
        assert sorted(p.name for p in (tmp_path / VICTIM).iterdir()) == ["keep.txt"]
    assert not [p for p in tmp_path.rglob("*") if (p.name.startswith(".lfbench-stage") or p.name.endswith(".tmp"))
                and not p.name.endswith(".planted")]


# --------------------------------------------------------------------------- random bytes into the readers

@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("fuzz")
    folder = _scene(tmp)
    write_pfm(tmp / "pred.pfm", np.zeros((SIZE, SIZE), np.float32))
    return folder


FILES = {  # which file of a scene / command the random bytes replace, and the command that reads it
    "parameters.cfg": lambda t, s: ["predict", "--method", "gt", "--input", s, "--out", t / "o.pfm"],
    "gt_disp_lowres.pfm": lambda t, s: ["predict", "--method", "gt", "--input", s, "--out", t / "o.pfm"],
    "input_Cam040.png": lambda t, s: ["predict", "--method", "planesweep:interval=1", "--input", s, "--out",
                                      t / "o.pfm"],
}


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(sorted(FILES)), data=st.binary(max_size=300))
def test_random_bytes_never_give_a_traceback(tmp_path_factory, base, capsys, name, data):
    import shutil

    tmp = tmp_path_factory.mktemp("case")
    scene = tmp / "tiny"
    shutil.copytree(base, scene)
    (scene / name).write_bytes(data)
    rc, _, err = run_cli(capsys, *FILES[name](tmp, scene))
    assert "Traceback" not in err
    if rc != 0:
        assert_one_error_line(rc, err, name)
        assert not (tmp / "o.pfm").exists()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=8),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                  max_size=4), max_leaves=20))
def test_random_json_golden_files_are_validated(tmp_path_factory, capsys, value):
    tmp = tmp_path_factory.mktemp("golden")
    golden = _file(tmp, "g.json", json.dumps(value))
    new = _file(tmp, "r.json", "[]")
    rc, out, err = run_cli(capsys, "regress", golden, new)
    assert "Traceback" not in err
    assert rc in (1, 2), (rc, out, err)  # never 0: empty results pass no golden file, not even an empty one
    if rc == 1:  # a valid golden file: its records are missing, or it holds none and nothing was compared
        assert out.strip().splitlines()[-1].startswith("FAIL: 0 compared") or "MISSING" in out, out
    else:
        assert_one_error_line(rc, err, "g.json")
