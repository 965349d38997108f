"""Careless and hostile input (issue 12): wrong numbers with exit 0, unbounded sizes, disclosures.

Every case runs the CLI and expects exit 2, exactly one line on stderr that names the file or option,
no traceback and nothing written; the numeric cases compare against an independent reference."""

from __future__ import annotations

import json
import os
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line as one_line
from helpers import run_cli, write_scene, write_submission
from PIL import Image

from lfbench.data.hci import HCIScene
from lfbench.data.pfm import write_pfm

SIZE = 32  # px: 2 px scored inside the 15 px border (a border that leaves none is refused)


@pytest.fixture()
def scene(tmp_path) -> Path:
    return write_scene(tmp_path / "data", "tiny", "training", size=SIZE, seed=3)


def _set_cfg(folder: Path, key: str, value: str) -> None:
    cfg = folder / "parameters.cfg"
    lines = [f"{key} = {value}" if line.split("=")[0].strip() == key else line
             for line in cfg.read_text().splitlines()]
    cfg.write_text("\n".join(lines) + "\n")


# --------------------------------------------------------------------------- 12.2 wrong numbers with exit 0

def test_sixteen_bit_gray_views_read_as_their_8_bit_equivalent(tmp_path, scene):
    """A 16-bit gray PNG (mode I;16) used to be clipped to 255 by Pillow: ~99.9 % white views."""
    from lfbench.training.data import read_views_uint8

    eight = write_scene(tmp_path / "d8", "tiny", "training", size=SIZE, seed=3)
    sixteen = write_scene(tmp_path / "d16", "tiny", "training", size=SIZE, seed=3)
    for k in range(81):
        name = f"input_Cam{k:03d}.png"
        gray = np.asarray(Image.open(scene / name).convert("L"))
        Image.fromarray(gray).save(eight / name)
        Image.fromarray(gray.astype(np.uint16) * 257).save(sixteen / name)
    assert Image.open(sixteen / "input_Cam000.png").mode.startswith("I")
    ref, got = HCIScene(eight).gray_views(), HCIScene(sixteen).gray_views()
    assert np.abs(ref - got).max() < 1e-6
    assert ref.mean() < 0.9  # the views are not white
    np.testing.assert_array_equal(read_views_uint8(HCIScene(sixteen)), read_views_uint8(HCIScene(eight)))


def test_method_that_runs_on_no_scene_is_an_error_and_keeps_previous_results(tmp_path, capsys, scene):
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", "gt", "--out", out,
                         "--no-progress")
    assert rc == 0, err
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    for spec in ("subfocal:weights=/nonexistent.pt", f"published:path={write_submission(tmp_path / 'sub', {})}"):
        (tmp_path / "sub" / "disp_maps").mkdir(parents=True, exist_ok=True)
        rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", spec, "--out", out,
                             "--no-progress")
        one_line(rc, err, "cannot run on any selected scene (tiny)")
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_map_path_that_is_a_folder_is_an_error(tmp_path, capsys, scene):
    sub = tmp_path / "sub"
    (sub / "disp_maps" / "tiny.pfm").mkdir(parents=True)
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", f"published:path={sub}",
                         "--out", tmp_path / "out")
    one_line(rc, err, "tiny.pfm", "is a folder")
    assert not (tmp_path / "out").exists()


def test_submission_without_the_requested_scene_is_an_error(tmp_path, capsys, scene):
    write_scene(tmp_path / "data", "other", "training", size=SIZE)
    sub = write_submission(tmp_path / "sub", {"other": np.zeros((SIZE, SIZE), np.float32)})
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--scenes", "tiny",
                         "--method", f"published:path={sub}", "--out", tmp_path / "out")
    one_line(rc, err, "cannot run on any selected scene (tiny)", "tiny.pfm")


@pytest.mark.parametrize(("gt", "problem"), [
    (np.full((SIZE, SIZE), np.nan, np.float32), f"{SIZE * SIZE} non-finite values"),
    (np.where(np.eye(SIZE, dtype=bool), np.inf, 0).astype(np.float32), f"{SIZE} non-finite values"),
    (np.zeros((SIZE, SIZE, 3), np.float32), "3-channel PF map"),
])
def test_bad_ground_truth_is_blamed_not_the_method(tmp_path, capsys, scene, gt, problem):
    write_pfm(scene / "gt_disp_lowres.pfm", gt)
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", "gt",
                         "--out", tmp_path / "out")
    one_line(rc, err, "gt_disp_lowres.pfm", problem)
    assert not (tmp_path / "out" / "results.json").exists()


# --------------------------------------------------------------------------- 12.8 disclosure

def test_published_symlink_out_of_the_folder_is_refused_without_echoing(tmp_path, capsys, scene):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET-password-1\n")
    sub = tmp_path / "sub"
    (sub / "disp_maps").mkdir(parents=True)
    os.symlink(secret, sub / "disp_maps" / "tiny.pfm")
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", f"published:path={sub}",
                         "--out", tmp_path / "out")
    one_line(rc, err, "tiny.pfm", "symbolic link leading out of the submission folder")
    assert "TOPSECRET" not in err


def test_pfm_errors_never_echo_file_content(tmp_path, capsys, scene):
    sub = tmp_path / "sub"
    (sub / "disp_maps").mkdir(parents=True)
    (sub / "disp_maps" / "tiny.pfm").write_text("TOPSECRET-password-1\n")
    (sub / "runtimes").mkdir()
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", f"published:path={sub}",
                         "--out", tmp_path / "out")
    one_line(rc, err, "tiny.pfm", "not a PFM file")
    assert "TOPSECRET" not in err
    write_pfm(sub / "disp_maps" / "tiny.pfm", np.zeros((SIZE, SIZE), np.float32))
    (sub / "runtimes" / "tiny.txt").write_text("TOPSECRET-password-2\n")
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", f"published:path={sub}",
                         "--out", tmp_path / "out")
    one_line(rc, err, "tiny.txt", "runtime is not a number")
    assert "TOPSECRET" not in err


# --------------------------------------------------------------------------- 12.3 / 12.7 sizes from files

@pytest.mark.parametrize(("key", "value", "problem"), [
    ("num_cams_x", "100000", "num_cams_x = 100000 must be a whole number from 1 to 33"),
    ("num_cams_y", "0", "num_cams_y = 0 must be a whole number from 1 to 33"),
    ("image_resolution_x_px", "-64", "image_resolution_x_px = -64 must be a whole number from 1 to"),
    ("image_resolution_x_px", "1e9", "image_resolution_x_px = 1e+09 must be a whole number"),
    ("image_resolution_y_px", "inf", "image_resolution_y_px = inf must be a finite number"),
    ("image_resolution_y_px", "nan", "image_resolution_y_px = nan must be a finite number"),
    ("image_resolution_y_px", "24.5", "must be a whole number"),
    ("image_resolution_y_px,image_resolution_x_px", "16000,16000", "more than lfbench reads"),
    ("depth_map_scale", "nan", "depth_map_scale = nan must be a finite number"),
    ("depth_map_scale", "inf", "depth_map_scale = inf must be a finite number"),
    ("depth_map_scale", "0", "depth_map_scale = 0 must be a whole number from 1 to"),
    ("focal_length_mm", "0", "focal_length_mm = 0 must be > 0"),
    ("baseline_mm", "-inf", "baseline_mm = -inf must be a finite number"),
    ("disp_min", "nan", "disp_min = nan must be a finite number"),
])
def test_bad_parameters_cfg_is_one_line(tmp_path, capsys, scene, key, value, problem):
    for k, v in zip(key.split(","), value.split(","), strict=True):
        _set_cfg(scene, k, v)
    for args in (("predict", "--method", "planesweep", "--input", scene, "--out", tmp_path / "p.pfm"),
                 ("evaluate", "--data", tmp_path / "data", "--method", "gt", "--out", tmp_path / "out")):
        rc, _, err = run_cli(capsys, *args)
        one_line(rc, err, "parameters.cfg", problem)
    assert not (tmp_path / "p.pfm").exists() and not (tmp_path / "out").exists()


def _png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG whose header claims width x height 8-bit gray, with one tiny (truncated) IDAT chunk."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                     + chunk(b"IEND", b""))


def test_png_dimensions_are_checked_from_the_header_before_decoding(tmp_path, capsys, scene):
    _png_header_only(scene / "input_Cam040.png", 9600, 9600)
    rc, _, err = run_cli(capsys, "predict", "--method", "planesweep", "--input", scene, "--out", tmp_path / "p.pfm")
    one_line(rc, err, "input_Cam040.png", f"view is 9600x9600, parameters.cfg says {SIZE}x{SIZE}")
    from lfbench.data.scene import read_mask
    from lfbench.utils.errors import DataError

    _png_header_only(tmp_path / "big.png", 12000, 12000)  # below Pillow's bomb error, above our limit
    with pytest.raises(DataError, match="big.png: mask is 12000x12000 px, more than lfbench reads"):
        read_mask(tmp_path / "big.png")
    _png_header_only(tmp_path / "huge.png", 40000, 40000)  # beyond Pillow's own bomb limit too
    with pytest.raises(DataError, match="huge.png: mask is larger than lfbench reads"):
        read_mask(tmp_path / "huge.png")


def test_results_json_nested_too_deeply_is_one_line(tmp_path, capsys):
    path = tmp_path / "results.json"
    path.write_text("[" * 100000 + "]" * 100000)
    rc, _, err = run_cli(capsys, "report", path, "--out", tmp_path / "rep")
    one_line(rc, err, "results.json", "nested")
    path.write_text(json.dumps({"records": [], "runs": [{"method": 1}]}))
    rc, _, err = run_cli(capsys, "report", path, "--out", tmp_path / "rep")
    one_line(rc, err, "results.json", "run 0 is malformed")


@pytest.mark.parametrize(("spec", "problem"), [
    ("planesweep:interval=0.00001", "gives 8e+05 disparities, more than 1024"),
    ("planesweep:d_min=-1e9", "disparities beyond +-64"),
    ("planesweep:d_max=inf", "planesweep:d_max: must be a finite number, got inf"),
    ("planesweep:interval=inf", "planesweep:interval: must be a finite number, got inf"),
    ("planesweep:interval=nan", "planesweep:interval: must be a finite number, got nan"),
    ("planesweep:norm_radius=100000000", "norm_radius: must be in [0, 256], got 100000000"),
    ("planesweep:arm_length=1000000000", "arm_length: must be in [0, 256], got 1000000000"),
    ("planesweep:arm_tau=inf", "planesweep:arm_tau: must be a finite number, got inf"),
    ("subfocal:width=10000000", "width: must be in [1, 1024], got 10000000"),
    ("subfocal:interval=1e-7", "more than 1024"),
    ("subfocal:max_memory_gb=inf", "subfocal:max_memory_gb: must be a finite number, got inf"),
])
def test_spec_sizes_are_bounded_before_any_work(tmp_path, capsys, scene, spec, problem):
    rc, _, err = run_cli(capsys, "predict", "--method", spec, "--input", scene, "--out", tmp_path / "p.pfm")
    one_line(rc, err, spec.split(":")[0], problem)
    assert not (tmp_path / "p.pfm").exists()


def _npy_header_only(path: Path, shape: tuple[int, ...], descr: str = "<f4", payload: bytes = b"") -> None:
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": descr, "fortran_order": False, "shape": shape})
        f.write(payload)


@pytest.mark.parametrize(("shape", "payload", "problem"), [
    ((100000, 100000, 81), b"\0" * 64, "views of 100000x100000 px"),
    ((0, 4, 81), b"", "views of 4x0 px: each side must be from 1"),
    ((4, 4, 81), b"\0" * 100, "truncated .npy"),
    ((2, 2, 80), b"\0" * 1280, "square A x A grid (N = A^2, A from 2 to 33, e.g. 81 for 9x9), got shape (2, 2, 80)"),
])
def test_npy_header_is_checked_before_loading(tmp_path, capsys, shape, payload, problem):
    path = tmp_path / "views.npy"
    _npy_header_only(path, shape, payload=payload)
    rc, _, err = run_cli(capsys, "predict", "--method", "gt", "--input", path, "--out", tmp_path / "o.pfm")
    one_line(rc, err, "views.npy", problem)


def test_size_flags_are_bounded(tmp_path, capsys):
    rc, _, err = run_cli(capsys, "validate-submission", tmp_path, "--size", "60000")
    one_line(rc, err, "--size '60000'", "at most 16384 px")
    rc, _, err = run_cli(capsys, "synth", "--out", tmp_path / "s", "--size", "200000")
    one_line(rc, err, "size: must be in [16, 4096], got 200000")
    rc, _, err = run_cli(capsys, "synth", "--out", tmp_path / "s", "--angular", "99")
    one_line(rc, err, "argument --angular: must be in [3, 33], got 99")
    assert not (tmp_path / "s").exists()


# --------------------------------------------------------------------------- 12.3 / 12.7 tampered checkpoints

@pytest.fixture(scope="module")
def small_checkpoint(tmp_path_factory) -> Path:
    import torch
    from lfbench_methods.subfocal.keras_import import save_checkpoint
    from lfbench_methods.subfocal.network import SubFocalNet

    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("ckpt") / "small.pt"
    save_checkpoint(SubFocalNet(width=2, interval=1.0), path, "test")
    return path


def _tampered(small_checkpoint: Path, tmp_path: Path, change) -> Path:
    import torch

    ckpt = torch.load(small_checkpoint, weights_only=True)
    change(ckpt)
    out = tmp_path / "tampered.pt"
    torch.save(ckpt, out)
    return out


@pytest.mark.parametrize(("change", "problem"), [
    (lambda c: c["config"].update(width=10**7), "width: must be in [1, 1024], got 10000000"),
    (lambda c: c["config"].update(width=2.5), "width: expected int, got float"),
    (lambda c: c["config"].update(angular=100001), "angular: must be in [1, 15], got 100001"),
    (lambda c: c["config"].update(interval=1e-7), "more than 1024"),
    (lambda c: c["config"].update(d_max=float("inf")), "must be finite"),
    (lambda c: c["state_dict"].pop(next(iter(c["state_dict"]))), "missing 1 tensors (e.g. 'extractor."),
    (lambda c: c["state_dict"].update(bogus=np.zeros(1)), "1 unexpected entries (e.g. 'bogus')"),
    (lambda c: c["state_dict"].update({k: v[:1] for k, v in list(c["state_dict"].items())[:1]}), "has shape (1,"),
])
def test_tampered_checkpoint_is_one_line_naming_the_file(tmp_path, capsys, scene, small_checkpoint, change, problem):
    import torch

    def apply(c):
        change(c)
        for k, v in list(c["state_dict"].items()):
            if isinstance(v, np.ndarray):
                c["state_dict"][k] = torch.from_numpy(v)

    path = _tampered(small_checkpoint, tmp_path, apply)
    rc, _, err = run_cli(capsys, "predict", "--method", f"subfocal:weights={path}", "--input", scene,
                         "--out", tmp_path / "p.pfm")
    one_line(rc, err, "tampered.pt", problem)
    assert not (tmp_path / "p.pfm").exists()
