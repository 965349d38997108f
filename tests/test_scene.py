"""Scenes: HCI folder loading (lazy), view order and gray conversion, parameters.cfg and depth <-> disparity,
benchmark discovery and splits, masks, bad scene folders."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import ANGULAR, scene_parameters, write_scene
from PIL import Image
from scipy import ndimage

from lfbench.data.hci import HCIDataset, HCIScene
from lfbench.data.hci.params import read_parameters
from lfbench.data.pfm import write_pfm
from lfbench.data.scene import ArrayLightField, read_mask, rgb_to_gray
from lfbench.utils.errors import DataError

# --------------------------------------------------------------------------- views


def _gray_by_hand(path) -> np.ndarray:
    rgb = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)
    return (0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]) / 255.0


def test_scene_metadata_and_lazy_loading(tmp_path):
    folder = write_scene(tmp_path, "tiny", "training", size=40)
    (folder / "input_Cam005.png").write_bytes(b"not a png")  # lazy: not read until views are asked for
    scene = HCIScene(folder, category="training")
    assert (scene.name, scene.category, scene.angular_size, scene.spatial_size) == ("tiny", "training", (9, 9),
                                                                                     (40, 40))
    assert scene.has_gt() and not scene.has_gt("highres")
    assert scene.gt_disparity().shape == (40, 40)
    with pytest.raises(DataError) as info:
        scene.gray_views()
    assert "input_Cam005.png" in str(info.value) and "cannot read view image" in str(info.value)


def test_views_are_indexed_v_u_and_gray_is_the_weighted_sum(tmp_path):
    folder = write_scene(tmp_path, "tiny", size=24, seed=3)
    views = HCIScene(folder).gray_views()
    assert views.shape == (9, 9, 24, 24) and views.dtype == np.float32
    for k in (0, 1, 8, 9, 40, 44, 80):
        expected = _gray_by_hand(folder / f"input_Cam{k:03d}.png")
        np.testing.assert_allclose(views[k // 9, k % 9], expected, atol=1e-6)
    assert np.array_equal(views.reshape(81, 24, 24)[17], views[1, 8])


def test_view_geometry_follows_the_benchmark_convention(tmp_path):
    # a plane at d = 2: centre(x, y) = view_{u,v}(x - (u-4) d, y - (v-4) d) (u along x, v along y)
    d = 2
    views = HCIScene(write_scene(tmp_path, "plane", size=40, view_disparity=d)).gray_views()
    centre = views[4, 4]
    for v, u in ((4, 8), (0, 4), (1, 7), (8, 0)):
        shifted = np.roll(views[v, u], ((v - 4) * d, (u - 4) * d), axis=(0, 1))
        assert np.array_equal(shifted, centre), (v, u)
    # the transposed convention does not hold
    assert not np.array_equal(np.roll(views[4, 8], (4 * d, 0), axis=(0, 1)), centre)


def test_rgb_to_gray():
    rgb = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]], dtype=np.float32)
    np.testing.assert_allclose(rgb_to_gray(rgb), [[0.299, 0.587, 0.114, 1.0]], atol=1e-7)


def test_array_light_field_from_channels():
    stack = np.zeros((3, 5, 81), dtype=np.float32)
    stack[:] = np.arange(81, dtype=np.float32) / 80
    lf = ArrayLightField.from_channels(stack)
    assert lf.angular_size == (9, 9) and lf.gray_views().shape == (9, 9, 3, 5)
    assert lf.gray_views()[2, 7, 0, 0] == pytest.approx((2 * 9 + 7) / 80)
    assert lf.gt_disparity() is None
    with pytest.raises(ValueError):
        ArrayLightField.from_channels(np.zeros((3, 5, 80), dtype=np.float32))


# --------------------------------------------------------------------------- bad scene folders


def test_missing_views_name_them(tmp_path):
    folder = write_scene(tmp_path, "holes", size=16)
    for k in (3, 40, 41, 42, 80):
        (folder / f"input_Cam{k:03d}.png").unlink()
    with pytest.raises(DataError) as info:
        HCIScene(folder).gray_views()
    msg = str(info.value)
    assert str(folder) in msg and "missing 5 of 81 views" in msg and "input_Cam003.png" in msg and "\n" not in msg


def test_view_of_the_wrong_size(tmp_path):
    folder = write_scene(tmp_path, "odd", size=16)
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(folder / "input_Cam007.png")
    with pytest.raises(DataError, match="input_Cam007.png: view is 8x8, parameters.cfg says 16x16"):
        HCIScene(folder).gray_views()


def test_missing_cfg(tmp_path):
    folder = write_scene(tmp_path, "nocfg", size=16, views=False)
    (folder / "parameters.cfg").unlink()
    with pytest.raises(DataError, match="parameters.cfg: missing parameters.cfg"):
        HCIScene(folder)


@pytest.mark.parametrize("key", ["focal_length_mm", "num_cams_x", "baseline_mm", "focus_distance_m"])
def test_cfg_without_a_required_key(tmp_path, key):
    folder = write_scene(tmp_path, "nokey", size=16, views=False)
    cfg = folder / "parameters.cfg"
    cfg.write_text("\n".join(line for line in cfg.read_text().splitlines() if not line.startswith(key)))
    with pytest.raises(DataError) as info:
        HCIScene(folder)
    assert f"missing required key [{'intrinsics' if key == 'focal_length_mm' else 'extrinsics'}] {key}" in str(
        info.value)
    assert str(cfg) in str(info.value)


def test_cfg_with_a_non_number_and_garbage(tmp_path):
    folder = write_scene(tmp_path, "bad", size=16, views=False)
    cfg = folder / "parameters.cfg"
    cfg.write_text(cfg.read_text().replace("baseline_mm = 30.0", "baseline_mm = thirty"))
    with pytest.raises(DataError, match="baseline_mm = 'thirty' is not a number"):
        read_parameters(cfg)
    cfg.write_text("this is not an ini file")
    with pytest.raises(DataError, match="cannot parse"):
        read_parameters(cfg)


def test_ground_truth_of_the_wrong_size(tmp_path):
    folder = write_scene(tmp_path, "gt", size=16, views=False)
    write_pfm(folder / "gt_disp_lowres.pfm", np.zeros((8, 16), np.float32))
    with pytest.raises(DataError, match="ground truth is 16x8, expected 16x16"):
        HCIScene(folder).gt_disparity()


# --------------------------------------------------------------------------- parameters


def test_cfg_round_trip_and_toolkit_depth_to_disparity(tmp_path):
    params = scene_parameters("s", "training", 512)
    path = tmp_path / "parameters.cfg"
    path.write_text(params.to_cfg())
    back = read_parameters(path)
    assert back == params
    assert back.angular_size == (ANGULAR, ANGULAR) and back.spatial_size == (512, 512)
    depth = np.array([2.0, 8.3, 50.0])
    # toolkit's depth2disp: f = b/1000 * focal * max(W, H); (f F / Z - f) / F / sensor
    f = (30.0 / 1000.0) * 100.0 * 512
    expected = (f * 8.3 / depth - f) / 8.3 / 35.0
    np.testing.assert_allclose(back.depth_to_disparity(depth), expected, rtol=1e-12)
    assert back.depth_to_disparity(np.array(8.3)) == pytest.approx(0.0, abs=1e-12)  # the focus plane
    assert back.depth_to_disparity(np.array(2.0)) > 0  # closer than focus: positive
    np.testing.assert_allclose(back.disparity_to_depth(back.depth_to_disparity(depth)), depth, rtol=1e-12)


def test_real_scene_parameters(hci_root):
    scene = HCIScene(hci_root / "stratified" / "backgammon")
    assert scene.angular_size == (9, 9) and scene.spatial_size == (512, 512)
    assert scene.params.focus_distance_m == pytest.approx(8.3, abs=1e-6)
    assert (scene.params.disp_min, scene.params.disp_max) == (-1.7, 0.7)
    gt = scene.gt_disparity()
    assert gt.shape == (512, 512) and np.isfinite(gt).all()


def test_real_geometry_sign(hci_root):
    """centre(x, y) = view_{u,v}(x - (u-4) d, y - (v-4) d) on backgammon: clearly better than the opposite sign."""
    scene = HCIScene(hci_root / "stratified" / "backgammon")
    gt = scene.gt_disparity().astype(np.float64)
    centre = _gray_by_hand(scene.view_path(40))
    yy, xx = np.mgrid[0:512, 0:512].astype(np.float64)
    errors = {}
    for sign in (1, -1):
        errs = []
        for k in (44, 4):  # u = 8, v = 4 and u = 4, v = 0
            u, v = k % 9, k // 9
            view = _gray_by_hand(scene.view_path(k))
            warped = ndimage.map_coordinates(view, [yy - sign * (v - 4) * gt, xx - sign * (u - 4) * gt], order=1)
            errs.append(np.abs(warped - centre)[40:-40, 40:-40])
        errors[sign] = float(np.median(np.concatenate(errs)))
    assert errors[1] < 0.01 and errors[1] * 2 < errors[-1]


# --------------------------------------------------------------------------- benchmark layout


def _layout(tmp_path):
    for cat, name in (("stratified", "dots"), ("training", "boxes"), ("additional", "pens"), ("test", "herbs"),
                      ("mine", "synth_0")):
        write_scene(tmp_path, name, cat, size=8, views=False)
    (tmp_path / "training" / "not_a_scene").mkdir()
    return HCIDataset.open(tmp_path)


def test_discover_categories_and_splits(tmp_path):
    bench = _layout(tmp_path)
    assert sorted(bench.names) == ["boxes", "dots", "herbs", "pens", "synth_0"]
    assert {s.name: s.category for s in bench} == {"dots": "stratified", "boxes": "training", "pens": "additional",
                                                   "herbs": "test", "synth_0": "mine"}
    assert [s.name for s in bench.split("train")] == ["pens"]
    assert sorted(s.name for s in bench.split("validation")) == ["boxes", "dots"]
    assert [s.name for s in bench.split("test")] == ["herbs"]
    assert [s.name for s in bench.select(["boxes", "stratified"])] == ["boxes", "dots"]
    assert len(bench.select([])) == 5
    with pytest.raises(DataError, match="no scene 'nope'"):
        bench.select(["nope"])
    with pytest.raises(DataError, match="unknown split"):
        bench.split("dev")


def test_discover_a_single_scene_and_a_flat_folder(tmp_path):
    folder = write_scene(tmp_path, "one", "cat", size=8, views=False)
    assert HCIDataset.open(folder).names == ["one"]
    assert HCIDataset.open(tmp_path / "cat").names == ["one"]


def test_empty_or_missing_data_root(tmp_path):
    with pytest.raises(DataError, match="no scenes found"):
        HCIDataset.open(tmp_path)
    with pytest.raises(DataError, match="data root not found"):
        HCIDataset.open(tmp_path / "missing")


def test_masks(tmp_path):
    mask = np.zeros((8, 8), bool)
    mask[2:5, 3:6] = True
    folder = write_scene(tmp_path, "m", size=8, views=False, masks={"mask_planes_lowres": mask,
                                                                     "mask_fine_highres": mask})
    scene = HCIScene(folder)
    assert scene.mask_names("lowres") == ["mask_planes"]  # gt_disp_lowres.pfm is not a mask
    assert scene.mask_names("highres") == ["mask_fine"]
    assert np.array_equal(scene.mask("mask_planes"), mask)
    with pytest.raises(DataError, match="no mask"):
        scene.mask("mask_nope")
    assert scene.valid_mask() is None
    rgba = np.zeros((8, 8, 4), np.uint8)
    rgba[..., 3] = 255  # opaque black: alpha is ignored
    rgba[1, 1, 2] = 10
    Image.fromarray(rgba).save(folder / "valid_mask.png")
    valid = read_mask(folder / "valid_mask.png")
    assert valid.sum() == 1 and valid[1, 1]
