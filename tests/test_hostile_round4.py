"""Issue 39 (round four of the held-out audit), classes 2 to 4: a scene that cannot be read is one line naming
the file (never a smaller mean), values past float32 and borders past the views are refused before scoring,
metric plugins that collide, raise or return nonsense are one line naming the plugin, dataset adapters that
raise are isolated, PNG headers and TOML patterns are checked before anything is allocated, FIFOs never hang a
reader, and check-plugin has a time bound."""

from __future__ import annotations

import os
import shutil
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, run_cli, write_scene
from PIL import Image

from lfbench.data.generic import SPEC_FILE
from lfbench.data.pfm import write_pfm
from lfbench.data.synth_urbanlf import write_urbanlf

W, H = 48, 32  # UrbanLF stand-in: non-square and small


# --------------------------------------------------------------------------- roots to break

@pytest.fixture(scope="module")
def urban_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("urban")
    write_urbanlf(root, seed=3, width=W, height=H, scenes=2, split="val")
    return root


def _urban(urban_root: Path, tmp_path: Path) -> tuple[Path, Path]:
    """A writable copy of the UrbanLF root and the file its second sample's ground truth is in."""
    root = tmp_path / "urban"
    shutil.copytree(urban_root, root)
    return root, root / "val" / "Image2" / "5_5_disparity.npy"


def _hci(tmp_path: Path) -> tuple[Path, Path]:
    root = tmp_path / "hci"
    write_scene(root, "s0", "training", size=40)
    scene = write_scene(root, "s1", "training", size=40)
    return root, scene / "gt_disp_lowres.pfm"


def _toml(tmp_path: Path, fmt: str = "pfm", pattern: str = "v{k}.png", border: int = 2, extra: str = "") -> tuple[
        Path, Path]:
    """ROOT/lfbench-dataset.toml and two 3x3 scenes of 20x16 px views; the second scene's ground truth file."""
    root = tmp_path / "toml"
    root.mkdir()
    (root / SPEC_FILE).write_text(f'[views]\npattern = "{pattern}"\nangular = 3\nfirst = 1\n'
                                  f'[ground_truth]\nfile = "gt.{fmt}"\n[protocol]\nborder = {border}\n{extra}',
                                  encoding="utf-8")
    rng = np.random.default_rng(0)
    for name in ("s0", "s1"):
        scene = root / name
        scene.mkdir()
        for k in range(1, 10):
            Image.fromarray(rng.integers(0, 256, (16, 20, 3), dtype=np.uint8)).save(scene / f"v{k}.png")
        gt = np.zeros((16, 20), np.float32)
        np.save(scene / "gt.npy", gt) if fmt == "npy" else write_pfm(scene / "gt.pfm", gt)
    return root, root / "s1" / f"gt.{fmt}"


ROOTS: dict[str, Callable[[Path, Path], tuple[Path, Path]]] = {
    "urbanlf": _urban,
    "hci": lambda _, tmp: _hci(tmp),
    "toml": lambda _, tmp: _toml(tmp),
}


def _folder(path: Path) -> None:
    path.mkdir()


def _fifo(path: Path) -> None:
    os.mkfifo(path)


def _dev_zero(path: Path) -> None:
    path.symlink_to("/dev/zero")


def _dangling(path: Path) -> None:
    path.symlink_to(path.parent / "no-such-file")


def _loop(path: Path) -> None:
    path.symlink_to(path.name)  # a link to itself


UNREADABLE = {"folder": _folder, "fifo": _fifo, "dev_zero": _dev_zero, "dangling": _dangling, "loop": _loop}


def _replace(path: Path, make: Callable[[Path], None]) -> None:
    path.unlink()
    make(path)


# --------------------------------------------------------------------------- class 2: never a smaller mean

@pytest.mark.parametrize("kind", sorted(UNREADABLE))
@pytest.mark.parametrize("dataset", sorted(ROOTS))
def test_a_ground_truth_that_is_not_a_regular_file_is_one_line_never_a_dropped_scene(
        urban_root, tmp_path, capsys, dataset, kind):
    root, gt = ROOTS[dataset](urban_root, tmp_path)
    _replace(gt, UNREADABLE[kind])
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--method", "constant", "--out", out, "--no-progress")
    assert_one_error_line(rc, err, str(gt), "ground truth" if dataset != "hci" else "PFM file")
    assert not out.exists()  # nothing half-written


@pytest.mark.parametrize("kind", ["folder", "fifo", "dangling"])
def test_check_dataset_names_a_ground_truth_that_is_not_a_regular_file(urban_root, tmp_path, capsys, kind):
    root, gt = _urban(urban_root, tmp_path)
    _replace(gt, UNREADABLE[kind])
    rc, _, err = run_cli(capsys, "check-dataset", root, "--no-progress")
    assert_one_error_line(rc, err, str(gt), "ground truth")


@pytest.mark.parametrize("value", [1e300, -1e39, 3.5e38])
@pytest.mark.parametrize("dataset", ["urbanlf", "toml-npy"])
def test_float64_ground_truth_beyond_float32_is_refused_not_scored_as_inf(urban_root, tmp_path, capsys, dataset,
                                                                         value):
    if dataset == "urbanlf":
        root, gt = _urban(urban_root, tmp_path)
        shape = (H, W)
    else:
        root, gt = _toml(tmp_path, "npy")
        shape = (16, 20)
    data = np.zeros(shape, np.float64)
    data[3, 5] = value
    np.save(gt, data)
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--method", "constant", "--out", out, "--no-progress")
    assert_one_error_line(rc, err, str(gt), "1 non-finite values", "float32")
    assert "warning" not in err.lower() and not out.exists()


@pytest.mark.parametrize("border", [8, 10, 500])
def test_a_border_that_leaves_no_pixel_is_refused_before_scoring(tmp_path, capsys, border):
    root, _ = _toml(tmp_path, border=border)  # views 20x16: 2 x 8 = 16 leaves no row
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--method", "constant", "--out", out, "--no-progress")
    assert_one_error_line(rc, err, str(root / "s0"), f"border of {border} px", "20x16")
    assert not out.exists()


def test_a_border_that_leaves_one_row_still_scores(tmp_path, capsys):
    root, _ = _toml(tmp_path, border=7)  # 16 - 14 = 2 rows, 20 - 14 = 6 columns
    rc, _, err = run_cli(capsys, "-q", "evaluate", "--data", root, "--method", "constant", "--out", tmp_path / "o",
                         "--no-progress")
    assert rc == 0, err


# --------------------------------------------------------------------------- metric plugins

_PIXELWISE = '''
import numpy as np
from lfbench.scoring.metrics import Mean, Metric, OrderStatistic, PixelMetric, Sample


def sample(px, *, toolkit=False):
{body}


PLUG = Metric(id="{id}", name="Plug", description="", unit="px", pixelwise=PixelMetric(sample, {family}))
'''

_OF_MAPS = '''
import numpy as np
from lfbench.scoring.metrics import Metric


def score(gt, pred, mask=None, *, toolkit=False):
{body}


PLUG = Metric(id="{id}", name="Plug", description="", unit="px", fn=score)
'''


def _metric_plugin(tmp_path: Path, monkeypatch, text: str, metric_id: str = "plug") -> str:
    """A module holding ``PLUG`` installed as the entry point ``metric_id`` of lfbench.metrics (on sys.path and
    PYTHONPATH, for spawned workers too), the process-wide registry loading the group again (undone
    afterwards); returns the module's name."""
    import sys
    import uuid

    from helpers import write_dist_info

    from lfbench.scoring.metrics import METRICS

    METRICS.names()  # lfbench's own metrics registered (once per process: their module is imported once)
    module = f"plug_{uuid.uuid4().hex[:10]}"
    site = tmp_path / "site"
    site.mkdir(exist_ok=True)
    (site / f"{module}.py").write_text(text, encoding="utf-8")
    write_dist_info(site, f"plug-{module[5:]}", f"[lfbench.metrics]\n{metric_id} = {module}:PLUG\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")])))
    for attr in ("_objects", "_entries", "_aliases", "load_errors"):
        monkeypatch.setattr(METRICS, attr, dict(getattr(METRICS, attr)))
    monkeypatch.setattr(METRICS, "_loaded", False)
    monkeypatch.setattr(METRICS, "_refused", None)
    monkeypatch.delitem(sys.modules, module, raising=False)
    return module


def _indent(body: str) -> str:
    return "\n".join("    " + line for line in body.splitlines())


@pytest.fixture()
def hci_root(tmp_path) -> Path:
    write_scene(tmp_path / "data", "s0", "training", size=40)
    return tmp_path / "data"


PIXELWISE_CASES = {  # body of sample(px), family -> what the line says
    "raises": ("raise RuntimeError('boom')", "Mean(scale=1.0)", "failed: RuntimeError: boom"),
    "memory": ("np.zeros(10**12)\nreturn Sample(px.err, None)", "Mean(scale=1.0)", "failed: MemoryError"),
    "string": ("return 'abc'", "Mean(scale=1.0)", "returned a str, expected Sample"),
    "none": ("return None", "Mean(scale=1.0)", "returned a NoneType"),
    "array": ("return px.err", "Mean(scale=1.0)", "returned a ndarray, expected Sample"),
    "2d-values": ("return Sample(np.zeros((2, 2)), None)", "Mean(scale=1.0)", "values of float64 (2, 2)"),
    "text-values": ("return Sample(np.array(['a']), None)", "Mean(scale=1.0)", "expected a 1-D array of numbers"),
    "short-keep": ("keep = np.ones(px.size - 1, bool)\nreturn Sample(px.err[:-1], keep)", "Mean(scale=1.0)",
                   "a keep mask of bool"),
    "keep-count": ("keep = np.ones(px.size, bool)\nreturn Sample(px.err[:3], keep)", "Mean(scale=1.0)",
                   "3 values for"),
    "order-250": ("return Sample(px.err, None)", "OrderStatistic(250)", "OrderStatistic(250): the percentage"),
    "order-neg": ("return Sample(px.err, None)", "OrderStatistic(-1)", "OrderStatistic(-1): the percentage"),
}


@pytest.mark.parametrize("case", sorted(PIXELWISE_CASES))
def test_a_pixelwise_metric_plugin_that_misbehaves_is_one_line_naming_it(tmp_path, monkeypatch, capsys, hci_root,
                                                                         case):
    body, family, said = PIXELWISE_CASES[case]
    module = _metric_plugin(tmp_path, monkeypatch, _PIXELWISE.format(body=_indent(body), family=family, id="plug"))
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", hci_root, "--method", "constant", "--out", out,
                         "--no-progress", "--metrics", "plug")  # a plugin's metric is scored where asked for
    assert_one_error_line(rc, err, f"metric plugin {module}.sample", said)
    assert not out.exists()


@pytest.mark.parametrize(("body", "said"), [
    ("raise ValueError('bad')", "failed: ValueError: bad"),
    ("return 'abc'", "returned a str, expected a number"),
    ("return np.array([1.0, 2.0])", "returned a ndarray, expected a number"),
    ("return None", "returned a NoneType, expected a number"),
    ("return True", "returned a bool, expected a number"),
])
def test_a_metric_plugin_of_maps_that_misbehaves_is_one_line_naming_it(tmp_path, monkeypatch, capsys, hci_root, body,
                                                                      said):
    module = _metric_plugin(tmp_path, monkeypatch, _OF_MAPS.format(body=_indent(body), id="plug"))
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", hci_root, "--method", "constant", "--out", out,
                         "--no-progress", "--metrics", "plug")
    assert_one_error_line(rc, err, f"metric plugin 'plug' ({module}.score)", said)
    assert not out.exists()


@pytest.mark.parametrize(("flags", "body"), [
    (("--jobs", "2"), "raise RuntimeError('boom')"),  # in a spawned worker process
    (("--ci", "--ci-resamples", "20"), "keep = np.ones(px.size + 5, bool)\nreturn Sample(px.err, keep)"),
])
def test_metric_plugin_failures_in_workers_and_under_ci_are_one_line(tmp_path, monkeypatch, capsys, hci_root, flags,
                                                                     body):
    write_scene(hci_root, "s1", "training", size=40)
    module = _metric_plugin(tmp_path, monkeypatch, _PIXELWISE.format(body=_indent(body), family="Mean(scale=1.0)",
                                                                     id="plug"))
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", hci_root, "--method", "constant", "--out", out,
                         "--no-progress", "--metrics", "plug", *flags)
    assert_one_error_line(rc, err, f"metric plugin {module}.sample")
    assert not out.exists()


@pytest.mark.parametrize("metric_id", ["badpix_0.07", "badpix_0.075", "mse_x100", "q30_x100", "badpix_0070"])
def test_a_metric_plugin_that_takes_an_existing_id_is_refused_naming_both(tmp_path, monkeypatch, capsys, hci_root,
                                                                          metric_id):
    module = _metric_plugin(tmp_path, monkeypatch, _PIXELWISE.format(body="    return Sample(px.err, None)",
                                                                     family="Mean(scale=1.0)", id=metric_id),
                            metric_id=metric_id)
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", hci_root, "--method", "constant", "--out", out,
                         "--no-progress")
    line = assert_one_error_line(rc, err, f"metric plugin {metric_id!r} ({module}:PLUG) refused",
                                 f"metric {metric_id!r} is already")
    assert "lfbench.scoring" in line  # the metric it would replace, by its module
    assert not out.exists()


# --------------------------------------------------------------------------- check-plugin: exits and time

def _network(kind: str):
    """A small network whose constructor or forward exits the process or never ends (``kind``)."""
    import time

    from torch import nn

    class Net(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            if kind == "init-exit":
                raise SystemExit(0)
            if kind == "init-sleep":
                time.sleep(60)
            self.angular = 9
            self.conv = nn.Conv2d(81, 1, 3, padding=1)

        def forward(self, views):
            if kind == "forward-exit":
                raise SystemExit(0)
            if kind == "forward-exit-none":
                raise SystemExit
            if kind == "forward-loop":
                while True:
                    pass
            if kind == "forward-sleep":
                time.sleep(60)
            return self.conv(views)[:, 0], None

    return Net


@pytest.fixture()
def plugin_networks(monkeypatch):
    from helpers import isolate_registries

    from lfbench.method.trainable import Trainable, register_trainable

    isolate_registries(monkeypatch)
    for kind in ("init-exit", "init-sleep", "forward-exit", "forward-exit-none", "forward-loop", "forward-sleep"):
        register_trainable(f"net-{kind}")(type(f"Net_{kind.replace('-', '_')}", (Trainable,),
                                               {"network": _network(kind), "__module__": __name__}))


@pytest.mark.parametrize(("kind", "check"), [("init-exit", "build"), ("forward-exit", "forward"),
                                             ("forward-exit-none", "forward")])
def test_check_plugin_reports_a_network_that_exits_the_process_as_a_failure(plugin_networks, capsys, kind, check):
    rc, out, err = run_cli(capsys, "check-plugin", f"net-{kind}")
    assert rc == 1 and "Traceback" not in err, out + err
    failures = [line for line in out.splitlines() if line.startswith("FAIL")]
    assert len(failures) == 1 and failures[0].startswith(f"FAIL  {check}: "), out
    assert "SystemExit" in failures[0] and out.strip().splitlines()[-1].split(": ")[-2] == "FAILED"


@pytest.mark.parametrize(("kind", "check"), [("init-sleep", "the build check"), ("forward-loop", "the forward check"),
                                             ("forward-sleep", "the forward check")])
def test_check_plugin_bounds_the_time_of_a_constructor_and_a_forward(plugin_networks, capsys, kind, check):
    import time

    start = time.monotonic()
    rc, out, err = run_cli(capsys, "check-plugin", f"net-{kind}", "--timeout", "0.5")
    assert time.monotonic() - start < 20
    assert_one_error_line(rc, err, f"network 'net-{kind}'", check, "did not finish within 0.5 s (--timeout)")


def test_check_plugin_timeout_is_a_declared_flag_with_a_default(capsys):
    rc, out, _ = run_cli(capsys, "check-plugin", "--help")
    assert rc == 0 and "--timeout S" in out and "default 300" in out
    rc, _, err = run_cli(capsys, "check-plugin", "subfocal", "--timeout", "0")
    assert rc == 2 and "--timeout" in err and "Traceback" not in err


# --------------------------------------------------------------------------- class 1: ablate writes inside OUT

@pytest.fixture(scope="module")
def finished_ablation(tmp_path_factory):
    """A finished two-cell ablation (tests/test_ablation_reuse.py's), each test working on a copy."""
    from test_ablate import TWO_CELLS, write_spec

    from lfbench.ablation.runner import run_ablation
    from lfbench.ablation.spec import load_spec

    root = tmp_path_factory.mktemp("round4-ablate")
    spec = write_spec(root, TWO_CELLS, evaluation="error_maps = false\n")
    run_ablation(load_spec(spec), root / "out", progress=False, log=lambda _m: None)
    return spec, root / "out"


CELL = "interval=2"
_UNFINISHED = ("cell.json", "results.json", "final.pt", "summary.json", "timing.json", "checkpoint.pt")


def _ablation_copy(finished_ablation, tmp_path: Path) -> tuple[Path, Path, Path]:
    """(spec, a copy of OUT with cell interval=2 to train again, an outside folder with one file)."""
    spec, out = finished_ablation
    copy = tmp_path / "out"
    shutil.copytree(out, copy, symlinks=True)
    for name in _UNFINISHED:
        (copy / "cells" / CELL / name).unlink()
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep.txt").write_text("mine\n", encoding="utf-8")
    return spec, copy, outside


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() if p.is_file() else b"" for p in folder.rglob("*")}


def _link_data_folder(cell: Path, outside: Path) -> Path:
    shutil.rmtree(cell / "data")
    (cell / "data").symlink_to(outside, target_is_directory=True)
    return cell / "data"


def _link_checkpoint(cell: Path, outside: Path) -> Path:
    (outside / "checkpoint.pt").write_bytes(b"not yours")
    (cell / "checkpoint.pt").symlink_to(outside / "checkpoint.pt")
    return cell / "checkpoint.pt"


def _link_train_config(cell: Path, outside: Path) -> Path:
    (cell / "train.toml").unlink()
    (cell / "train.toml").symlink_to(outside / "keep.txt")
    return cell / "train.toml"


def _link_in_a_subfolder(cell: Path, outside: Path) -> Path:
    (cell / "maps").mkdir(exist_ok=True)
    (cell / "maps" / "deep").symlink_to(outside, target_is_directory=True)
    return cell / "maps" / "deep"


def _link_stage_weights(cell: Path, outside: Path) -> Path:
    weights = cell / "stage1_l1.pt"  # a stage's weights, re-used when the cell resumes
    weights.unlink()
    weights.symlink_to(outside / "keep.txt")
    return weights


def _link_log(cell: Path, outside: Path) -> Path:
    log = cell / "log.txt"  # the training appends to it
    log.unlink()
    log.symlink_to(outside / "keep.txt")
    return log


@pytest.mark.slow
@pytest.mark.parametrize("make", [_link_data_folder, _link_checkpoint, _link_train_config, _link_in_a_subfolder,
                                  _link_log, _link_stage_weights], ids=lambda f: f.__name__[1:])
def test_anything_below_a_cell_leading_out_of_out_is_refused_before_any_work(finished_ablation, tmp_path, capsys,
                                                                              make):
    spec, out, outside = _ablation_copy(finished_ablation, tmp_path)
    link = make(out / "cells" / CELL, outside)
    before_out, before_outside = _snapshot(out), _snapshot(outside)
    rc, _, err = run_cli(capsys, "ablate", spec, "--out", out, "--no-progress")
    assert_one_error_line(rc, err, str(link), "symbolic link leading out of the ablation folder")
    assert _snapshot(outside) == before_outside  # nothing read, generated or written there
    assert {k: v for k, v in _snapshot(out).items() if not k.endswith(".lock")} == \
        {k: v for k, v in before_out.items() if not k.endswith(".lock")}


@pytest.mark.slow
@pytest.mark.parametrize("target", ["empty", "other-scenes", "dangling"])
def test_a_data_link_that_leads_elsewhere_is_re_pointed_not_followed(finished_ablation, tmp_path, capsys, target):
    """The over-strict side: a cell's data link into another folder (an earlier version's, a copy's) is replaced
    by the right relative one, as the README says, instead of 'no scenes found' or reading that folder."""
    spec, out, outside = _ablation_copy(finished_ablation, tmp_path)
    elsewhere = outside / "synthetic"
    if target == "other-scenes":
        write_scene(outside, "stranger", "synthetic", size=40)
    elif target == "empty":
        elsewhere.mkdir()
    link = out / "cells" / CELL / "data" / "synthetic"
    link.unlink()
    link.symlink_to(elsewhere, target_is_directory=True)
    before_outside = _snapshot(outside)
    rc, _, err = run_cli(capsys, "-q", "ablate", spec, "--out", out, "--no-progress")
    assert rc == 0, err
    assert not Path(os.readlink(link)).is_absolute() and link.resolve().is_relative_to(out.resolve())
    assert (out / "cells" / CELL / "cell.json").is_file()
    assert _snapshot(outside) == before_outside


# --------------------------------------------------------------------------- class 3 and 4: headers, patterns,
# FIFOs and adapters

def _png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG whose IHDR says ``width`` x ``height`` (8-bit RGB) followed by IEND: no pixel data at all."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b""))


@pytest.mark.parametrize("command", ["evaluate", "check-dataset"])
@pytest.mark.parametrize(("dataset", "view"), [("urbanlf", "3_4.png"), ("urbanlf", "5_5.png"), ("toml", "v2.png"),
                                               ("hci", "input_Cam010.png")])
def test_a_view_that_is_a_fifo_is_one_line_never_a_hang(urban_root, tmp_path, capsys, command, dataset, view):
    if (dataset, command) == ("hci", "evaluate"):
        command = "evaluate-planesweep"  # the constant method reads no view of an HCI scene (checked when read)
    root, gt = ROOTS[dataset](urban_root, tmp_path)
    path = gt.parent / view
    _replace(path, _fifo)
    method = "planesweep:interval=1" if command == "evaluate-planesweep" else "constant"
    args = ["evaluate", "--data", root, "--method", method, "--out", tmp_path / "out", "--no-progress"] \
        if command.startswith("evaluate") else ["check-dataset", root, "--no-progress"]
    rc, _, err = run_cli(capsys, *args)
    assert_one_error_line(rc, err, str(path), "not a regular file")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("dataset", "views", "size", "said"), [
    ("urbanlf", ["2_7.png"], (20000, 20000), "20000x20000 px by its header"),
    ("urbanlf", ["5_5.png"], (70000, 3), "70000x3"),
    ("toml", ["v9.png"], (1, 2**31), "by its header"),
    ("urbanlf", "all", (10000, 10000), "GiB as float RGB"),
    ("toml", "all", (10000, 8000), "GiB as float RGB"),
])
def test_view_headers_are_bounded_before_anything_is_decoded_or_allocated(urban_root, tmp_path, capsys, dataset,
                                                                           views, size, said):
    root, gt = ROOTS[dataset](urban_root, tmp_path)
    names = sorted(p.name for p in gt.parent.glob("*.png")) if views == "all" else views
    for name in names:
        _png_header_only(gt.parent / name, *size)
    for command in (["evaluate", "--data", root, "--method", "constant", "--out", tmp_path / "out", "--no-progress"],
                    ["check-dataset", root, "--no-progress"]):
        rc, _, err = run_cli(capsys, *command)
        line = assert_one_error_line(rc, err, str(gt.parent), said)
        assert "DecompressionBomb" not in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("pattern", "shown"), [
    ("view_{v}_{u}{0}.png", "{0}"),
    ("view_{}_{v}_{u}.png", "{}"),
    ("v{k:>999999999}.png", "{k:>999999999}"),
    ("v{v:>9}_{u}.png", "{v:>9}"),
    ("v{k!r}.png", "{k!r}"),
    ("v{k.real}.png", "{k.real}"),
    ("v{k[0]}.png", "{k[0]}"),
    ("v{x}{k}.png", "{x}"),
])
def test_toml_view_patterns_hold_only_bare_fields(tmp_path, capsys, pattern, shown):
    root, _ = _toml(tmp_path, pattern=pattern)
    for command in (["evaluate", "--data", root, "--method", "constant", "--out", tmp_path / "out", "--no-progress"],
                    ["check-dataset", root, "--no-progress"]):
        rc, _, err = run_cli(capsys, *command)
        assert_one_error_line(rc, err, str(root / SPEC_FILE), "views.pattern: may hold only", shown[:40])


@pytest.mark.parametrize("pattern", ["v{k}}.png", "v{{k}.png", "v{k.png"])
def test_toml_view_patterns_with_unbalanced_braces_are_one_line(tmp_path, capsys, pattern):
    root, _ = _toml(tmp_path, pattern=pattern)
    rc, _, err = run_cli(capsys, "check-dataset", root, "--no-progress")
    assert_one_error_line(rc, err, str(root / SPEC_FILE), "views.pattern: has unbalanced braces")


class _Raising:
    """Dataset adapter bodies for a plugin (``kind`` says which hook raises)."""

    @staticmethod
    def make(kind: str):
        from lfbench.data.dataset import Dataset
        from lfbench.data.urbanlf import UrbanLFSyn

        class Plugin(Dataset):
            name = f"broken-{kind}"
            summary = layout = "a plugin"
            protocol = UrbanLFSyn.protocol

            @classmethod
            def matches(cls, root):
                if kind == "matches":
                    raise RuntimeError("cannot look")
                if kind == "matches-memory":
                    raise MemoryError
                return (Path(root) / "plugin.txt").is_file()

            @classmethod
            def open(cls, root):
                if kind == "open":
                    raise KeyError("no scenes here")
                return "not a benchmark"

        Plugin.__module__ = "broken_adapter"
        return Plugin


@pytest.fixture()
def broken_adapters(monkeypatch):
    from lfbench.data.dataset import DATASETS

    DATASETS.names()
    for attr in ("_objects", "_entries", "_aliases", "load_errors"):
        monkeypatch.setattr(DATASETS, attr, dict(getattr(DATASETS, attr)))
    for kind in ("matches", "matches-memory", "open", "returns"):
        DATASETS.add(f"broken-{kind}", _Raising.make(kind))


@pytest.mark.parametrize("dataset", ["urbanlf", "hci", "toml"])
def test_a_dataset_adapter_whose_matches_raises_breaks_no_other_root(broken_adapters, urban_root, tmp_path, capsys,
                                                                     dataset):
    root, _ = ROOTS[dataset](urban_root, tmp_path)
    rc, _, err = run_cli(capsys, "-q", "evaluate", "--data", root, "--method", "constant", "--out", tmp_path / "out",
                         "--no-progress")
    assert rc == 0, err
    assert "broken-matches" in err and "Traceback" not in err  # named in a warning, left out


@pytest.mark.parametrize(("kind", "said"), [("open", "open() failed: KeyError"),
                                            ("returns", "open() returned a str, expected a Benchmark"),
                                            ("matches", "matches() failed: RuntimeError: cannot look"),
                                            ("matches-memory", "matches() failed: MemoryError")])
def test_a_dataset_adapter_that_raises_is_one_line_naming_it(broken_adapters, tmp_path, capsys, kind, said):
    root = tmp_path / "plugin-root"
    root.mkdir()
    (root / "plugin.txt").write_text("x", encoding="utf-8")
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--dataset", f"broken-{kind}", "--method", "constant",
                         "--out", tmp_path / "out", "--no-progress")
    assert_one_error_line(rc, err, str(root), f"'broken-{kind}' (broken_adapter.", said)
    assert not (tmp_path / "out").exists()
