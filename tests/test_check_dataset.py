"""lfbench check-dataset: a dataset's own ground truth says how its view grid and disparity sign run.

References independent of the check: the renderer's geometry (a fronto-parallel plane at an integer disparity
is every view's exact shifted copy), grids re-indexed by hand (the data stored each of the 8 ways), and the
real HCI scenes, whose convention the benchmark's own files define."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_one_error_line, run_cli, write_scene
from PIL import Image

from lfbench.data.generic import SPEC_FILE
from lfbench.data.orientation import AS_READ, ORIENTATIONS, check_orientation, distinct_readings, warp_error
from lfbench.data.synth import generate_scene, plane_views, quantize

SIGN = ORIENTATIONS[1]
SWAPPED = ORIENTATIONS[4]


@pytest.fixture(scope="module")
def scene():
    return generate_scene(5, size=48, angular=7)


def _inverse(orientation):
    """The reading that undoes ``orientation`` (found on an index grid, not written by hand)."""
    grid = np.arange(49).reshape(7, 7)
    return next(o for o in ORIENTATIONS if np.array_equal(orientation.apply(o.apply(grid)), grid))


def test_a_plane_at_an_integer_disparity_warps_exactly_only_when_read_as_rendered():
    views = plane_views(1.0, 32, angular=5)
    disparity = np.ones((32, 32), np.float32)
    assert warp_error(views, disparity) < 1e-6  # whole-pixel shifts: every sample lands on a pixel
    assert warp_error(SIGN.apply(views), disparity) > 0.02
    assert warp_error(SWAPPED.apply(views), disparity) > 0.02
    assert warp_error(views, -disparity) == pytest.approx(warp_error(SIGN.apply(views), disparity), rel=1e-5)


def test_the_readings_are_the_eight_symmetries_of_the_grid():
    grid = np.arange(49).reshape(7, 7)
    images = {o.apply(grid).tobytes() for o in ORIENTATIONS}
    assert len(images) == 8
    assert all(o.apply(grid)[3, 3] == grid[3, 3] for o in ORIENTATIONS)  # the centre view stays the centre


@pytest.mark.parametrize("stored", ORIENTATIONS, ids=lambda o: o.name)
def test_each_way_of_storing_the_grid_is_recognised(scene, stored):
    """Views stored as ``stored`` describes (the inverse applied to the true grid): the check names ``stored``."""
    gray = _inverse(stored).apply(scene.gray_views())
    check = check_orientation("s", gray, scene.disparity)
    assert check.best is stored and check.decided
    assert check.agrees is (stored is AS_READ)


def test_ground_truth_of_the_opposite_sign_is_named_as_such(scene):
    check = check_orientation("s", scene.gray_views(), -scene.disparity)
    assert check.best is SIGN and check.decided and not check.agrees
    assert check.ratio > 1.25


def test_no_disparity_leaves_the_reading_undecided(scene):
    flat = np.broadcast_to(scene.gray_views()[3, 3], scene.gray_views().shape)
    check = check_orientation("s", flat, np.zeros_like(scene.disparity))
    assert check.ratio == 1.0 and not check.decided and not check.agrees


def test_a_row_of_views_has_two_readings_and_they_are_told_apart(scene):
    """On one row of views reversing the rows changes nothing and reversing the columns is negating the
    disparity: two readings remain, and the check still tells them apart."""
    assert distinct_readings(1, 7) == [AS_READ, SIGN]
    assert len(distinct_readings(3, 5)) == 4 and len(distinct_readings(7, 7)) == 8
    row = scene.gray_views()[3:4]
    check = check_orientation("s", row, scene.disparity)
    assert set(check.errors) == {AS_READ, SIGN} and check.agrees
    assert check_orientation("s", row[:, ::-1], scene.disparity).best is SIGN


def test_a_grid_without_a_centre_view_is_refused(scene):
    with pytest.raises(ValueError, match="odd size"):
        warp_error(scene.gray_views()[:6, :6], scene.disparity)


def _toml_dataset(root, scene, stored, *, gt_sign: float = 1.0, keys: str = ""):
    """A TOML dataset of one scene whose files hold the grid as ``stored`` describes, ground truth times
    ``gt_sign``; ``keys``: further TOML lines (``[views]`` keys first, then ``[ground_truth]``)."""
    root.mkdir(exist_ok=True)
    views_keys, _, gt_keys = keys.partition("[ground_truth]\n")
    (root / SPEC_FILE).write_text(f'[views]\npattern = "view_{{v}}_{{u}}.png"\nangular = 7\n{views_keys}'
                                  f'[ground_truth]\nfile = "gt.npy"\nformat = "npy"\n{gt_keys}[protocol]\nborder = 4\n')
    folder = root / "street"
    if not folder.is_dir():
        folder.mkdir()
        files = _inverse(stored).apply(quantize(scene.views))  # what the reading ``stored`` turns back
        for v in range(7):
            for u in range(7):
                Image.fromarray(files[v, u]).save(folder / f"view_{v}_{u}.png")
        np.save(folder / "gt.npy", gt_sign * scene.disparity)
    return root


#: check-dataset's first line on a good TOML dataset of one scene: the adapter's contract holds (issue 38)
TOML_ADAPTER_HOLDS = ("adapter 'toml' (lfbench.data.generic.GenericDataset): contract holds on 1 scene (views and "
                      "ground truth read on 1)")


def _orientation(out: str) -> str:
    """check-dataset's output after its first line, which says that the adapter's contract holds."""
    first, _, rest = out.partition("\n")
    assert first == TOML_ADAPTER_HOLDS, out
    return rest


@pytest.mark.parametrize("stored", ORIENTATIONS, ids=lambda o: o.name)
def test_cli_names_how_the_files_run_and_its_toml_fix_reads_them_right(scene, stored, tmp_path, capsys):
    root = _toml_dataset(tmp_path / "d", scene, stored)
    rc, out, _ = run_cli(capsys, "check-dataset", str(root), "--no-progress")
    assert _orientation(out).startswith(f"street: {stored.name}: mean error ")
    if stored is AS_READ:
        assert rc == 0 and "1 of 1 scenes with ground truth agree with lfbench's reading, 0 contradict" in out
        return
    assert rc == 1 and "0 of 1 scenes with ground truth agree with lfbench's reading, 1 contradict" in out
    assert f"CONTRADICTS lfbench's reading (toml); a TOML dataset would {stored.toml_fix}" in out
    fix = "".join(f"{key} = true\n" for key in stored.toml_keys)
    rc, out, _ = run_cli(capsys, "check-dataset", str(_toml_dataset(root, scene, stored, keys=fix)), "--no-progress",
                         "--details")
    assert rc == 0 and _orientation(out).startswith("street: as read (lfbench's convention)"), out
    assert len([line for line in out.splitlines() if line.startswith("    ")]) == 8  # --details: every reading


def test_cli_names_a_negated_ground_truth_and_a_negative_scale_fixes_it(scene, tmp_path, capsys):
    root = _toml_dataset(tmp_path / "neg", scene, AS_READ, gt_sign=-1.0)
    rc, out, _ = run_cli(capsys, "check-dataset", str(root), "--no-progress")
    assert rc == 1 and _orientation(out).startswith(f"street: {SIGN.name}") and "ground_truth.scale = -1" in out
    fixed = _toml_dataset(root, scene, AS_READ, keys="[ground_truth]\nscale = -1\n")
    rc, out, _ = run_cli(capsys, "check-dataset", str(fixed), "--no-progress")
    assert rc == 0 and _orientation(out).startswith("street: as read")


def test_a_toml_transpose_needs_a_square_grid(tmp_path, capsys):
    (tmp_path / SPEC_FILE).write_text('[views]\npattern = "v{v}_{u}.png"\nangular = [3, 5]\ntranspose = true\n')
    rc, _, err = run_cli(capsys, "check-dataset", str(tmp_path), "--no-progress")
    assert_one_error_line(rc, err, SPEC_FILE, "views.transpose: needs a square grid of views, got 3x5")


def test_cli_a_border_wider_than_the_scene_is_undecided_and_says_why(scene, tmp_path, capsys):
    root = _toml_dataset(tmp_path / "wide", scene, AS_READ)
    spec = root / SPEC_FILE
    spec.write_text(spec.read_text().replace("border = 4", "border = 30"))  # 48 px views: nothing inside
    rc, out, _ = run_cli(capsys, "check-dataset", str(root), "--no-progress")
    assert rc == 0 and "undecided (no pixel of the centre view inside the 30 px border" in out
    assert "0 of 1 scenes with ground truth agree with lfbench's reading, 0 contradict it, 1 undecided" in out


def test_cli_on_urbanlf_syn_layout_agrees(tmp_path, capsys):
    rc, _, err = run_cli(capsys, "synth", "--layout", "urbanlf-syn", "--out", str(tmp_path / "u"), "--size", "64x48",
                         "--scenes", "1", "--no-progress")
    assert rc == 0, err
    rc, out, _ = run_cli(capsys, "check-dataset", str(tmp_path / "u"), "--no-progress")
    assert rc == 0 and "urbanlf-syn at" in out and "1 of 1 scenes with ground truth agree" in out


def test_cli_without_ground_truth_is_one_line(tmp_path, capsys):
    folder = write_scene(tmp_path / "hci", "tiny", size=24)
    (folder / "gt_disp_lowres.pfm").unlink()
    rc, _, err = run_cli(capsys, "check-dataset", str(tmp_path / "hci"), "--no-progress")
    assert_one_error_line(rc, err, "none of the selected scenes has ground truth")


def test_cli_refuses_a_grid_without_a_centre_view_before_any_work(scene, tmp_path, capsys):
    root = tmp_path / "even"
    root.mkdir()
    (root / SPEC_FILE).write_text('[views]\npattern = "view_{v}_{u}.png"\nangular = 6\n'
                                  '[ground_truth]\nfile = "gt.npy"\n')
    folder = root / "street"
    folder.mkdir()
    views = quantize(scene.views)
    for v in range(6):
        for u in range(6):
            Image.fromarray(views[v, u]).save(folder / f"view_{v}_{u}.png")
    np.save(folder / "gt.npy", scene.disparity)
    rc, _, err = run_cli(capsys, "check-dataset", str(root), "--no-progress")
    assert_one_error_line(rc, err, "street", "the view grid is 6x6: check-dataset needs a centre view")


@pytest.mark.realdata
def test_the_real_hci_scenes_agree_with_lfbench_reading(hci_root, capsys):
    rc, out, _ = run_cli(capsys, "check-dataset", str(hci_root), "--scenes", "antinous", "--no-progress")
    assert rc == 0 and "antinous: as read (lfbench's convention)" in out
    ratio = float(out.split("antinous:", 1)[1].split("x\n", 1)[0].rsplit(", ", 1)[1])
    assert ratio > 2.0  # measured 3.12: the views tell the readings apart by far
