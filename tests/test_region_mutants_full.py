"""Tests that must fail: the survivors of the full mutation run in the region metrics, check_maps and protocol_of.

The bumpiness metric's function of maps (with and without its scene: the shared bumpiness map of a prepared
prediction, the ground truth's support kept per resolution, the plain route for any other ground truth or a
writeable prediction), the label values present (_present: the OR of bits and the chunked count), the gt-normal
rule of MAE, depth_normals' silenced floating-point events, backgammon's finite half-way values kept per column,
check_maps' messages and precision, and protocol_of's name and root. Each test names the class of mutants it
kills; every expected value is worked out by hand in its docstring or comment (the Scharr Hessian of a parabola
is 4 x its curvature: 8a for a c^2; a NaN reaches the 5 x 5 pixels around it). In-process, no subprocess.
Inputs are built in each test's body (no module-level cache: mutmut runs the tests in forked children).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from lfbench.data.dataset import protocol_of
from lfbench.data.generic import SPEC_FILE
from lfbench.scoring import region_metrics
from lfbench.scoring.general import check_maps
from lfbench.scoring.metrics import get_metric
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.prepare import SceneReference
from lfbench.scoring.region_metrics import _median_angle, _present, depth_normals
from lfbench.utils.errors import DataError

F32 = np.float32
A = 1.0 / 1024  # the parabola's coefficient: pred - gt = A c^2, exact in float32
BUMP = 100 * 8 * A  # 0.78125: 100 x the Scharr Hessian's norm 8A (4 x the curvature 2A) of A c^2, under the clip
CLIP = 0.05


def _parabola(n: int, factor: float = 1.0) -> np.ndarray:
    """(n, n) float32 factor x A c^2 (c the column): on rows and columns 2..n-3 its Scharr Hessian norm is
    factor x 8A exactly (only d/dx d/dx is non-zero; the zeroed outer ring of each pass stays 2 px away)."""
    c = np.arange(n, dtype=np.float64)
    return np.ascontiguousarray(np.broadcast_to(factor * A * c * c, (n, n)), dtype=F32)


def _interior(n: int) -> np.ndarray:
    mask = np.zeros((n, n), bool)
    mask[2:n - 2, 2:n - 2] = True
    return mask


def _read_only(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr)
    arr.flags.writeable = False
    return arr


# 13 x 13: the interior 2..10 is 9 x 9 = 81 pixels; a NaN at (6, 6) makes the 5 x 5 rows and columns 4..8 NaN
N = 13
WITH_25_CLIPPED = 100 * (25 * CLIP + 56 * 8 * A) / 81  # 2.0833...: the 25 at the clip value, 56 at 8A


class _Scene:
    """What SceneReference reads of a scene: ground truths by resolution and masks by (name, resolution)."""

    name = "pyramids"
    path = None
    params = None

    def __init__(self, gts: dict[str, np.ndarray], masks: dict[tuple[str, str], np.ndarray] | None = None) -> None:
        self.gts = gts
        self.masks = masks or {}

    @property
    def spatial_size(self) -> tuple[int, int]:
        return self.gts["lowres"].shape

    def gt_disparity(self, resolution: str = "lowres") -> np.ndarray | None:
        return self.gts.get(resolution)

    def mask(self, name: str, resolution: str = "lowres") -> np.ndarray:
        return self.masks[(name, resolution)]


def _gt_with_nan(n: int) -> np.ndarray:
    gt = np.zeros((n, n), F32)
    gt[n // 2, n // 2] = np.nan
    return gt


# --------------------------------------------------------------------------- bumpiness: the metric's function


def test_bumpiness_metric_of_maps_without_a_scene():
    """Kills _bump_fn's route without a scene (`is not None` for `is None`; gt, pred, mask or toolkit of its call
    None, dropped or shifted): the metric of maps alone. A NaN prediction at (6, 6): the toolkit leaves its 25
    pixels out (0.78125), lfbench's rule puts them at the clip value (2.0833...); without the mask the outer ring
    (0) would be scored."""
    gt = np.zeros((N, N), F32)
    pred = _parabola(N)
    pred[6, 6] = np.nan
    metric = get_metric("bumpiness_planes")
    assert metric(gt, pred, _interior(N), toolkit=True) == pytest.approx(BUMP, rel=1e-12)
    assert metric(gt, pred, _interior(N), toolkit=False) == pytest.approx(WITH_25_CLIPPED, rel=1e-12)
    assert metric(gt, pred, _interior(N)) == pytest.approx(WITH_25_CLIPPED, rel=1e-12)


def test_bumpiness_metric_with_its_scene_leaves_the_gt_support_out():
    """Kills the scene route's ground-truth support (gt_ok None, `toolkit or True`, a support computed as None,
    _bump_mean given None): the scene's own gt (NaN at (6, 6)) and a prepared (read-only) prediction; the 25
    pixels the NaN reaches are not scored in either rule, so both give 8A: 0.78125 (2.0833... if they were
    scored at the clip value)."""
    reference = SceneReference(_Scene({"lowres": _gt_with_nan(N)}))
    gt = reference.gt("lowres")
    pred = _read_only(_parabola(N))
    metric = get_metric("bumpiness_planes")
    for toolkit in (False, True):
        assert metric(gt, pred, _interior(N), scene=reference, resolution="lowres",
                      toolkit=toolkit) == pytest.approx(BUMP, rel=1e-12)


def test_bumpiness_metric_with_its_scene_for_another_gt_or_a_writeable_prediction():
    """Kills the plain route of the scene's metric (mask, toolkit, gt or pred of its call None, dropped or shifted)
    and its condition (`and` for `or`, `is` for `is not`): another ground truth, or a writeable prediction, is
    scored afresh each time. A writeable prediction changed in place (curvature doubled: 1.5625) is not served
    from a map kept for the object; two ground truths with one read-only prediction give their own values (8A,
    then 0 for the gt equal to the prediction); a NaN prediction is at the clip value or left out by rule."""
    reference = SceneReference(_Scene({"lowres": np.zeros((N, N), F32)}))
    gt = reference.gt("lowres")
    metric = get_metric("bumpiness_planes")
    mask = _interior(N)
    writeable = _parabola(N)
    assert metric(gt, writeable, mask, scene=reference, resolution="lowres") == pytest.approx(BUMP, rel=1e-12)
    writeable[:] = _parabola(N, 2.0)
    assert metric(gt, writeable, mask, scene=reference, resolution="lowres") == pytest.approx(2 * BUMP, rel=1e-12)
    pred = _read_only(_parabola(N))
    assert metric(np.zeros((N, N), F32), pred, mask, scene=reference, resolution="lowres") == pytest.approx(
        BUMP, rel=1e-12)
    assert metric(_parabola(N), pred, mask, scene=reference, resolution="lowres") == 0.0
    nan_pred = _parabola(N)
    nan_pred[6, 6] = np.nan
    other = np.zeros((N, N), F32)
    assert metric(other, nan_pred, mask, scene=reference, resolution="lowres",
                  toolkit=True) == pytest.approx(BUMP, rel=1e-12)
    assert metric(other, nan_pred, mask, scene=reference, resolution="lowres",
                  toolkit=False) == pytest.approx(WITH_25_CLIPPED, rel=1e-12)


def test_bumpiness_gt_support_is_kept_per_resolution():
    """Kills the support's cache key made None: the scene's low- and high-resolution ground truths (13 and 26 px,
    each NaN at its centre) keep their own supports; each value is 8A (the NaN's 25 pixels not scored), where a
    shared key would hand the 13 x 13 support to the 26 x 26 map."""
    n_high = 2 * N
    reference = SceneReference(_Scene({"lowres": _gt_with_nan(N), "highres": _gt_with_nan(n_high)}))
    metric = get_metric("bumpiness_planes")
    for resolution, n in (("lowres", N), ("highres", n_high)):
        value = metric(reference.gt(resolution), _read_only(_parabola(n)), _interior(n), scene=reference,
                       resolution=resolution)
        assert value == pytest.approx(BUMP, rel=1e-12)


def test_one_bumpiness_map_per_prepared_prediction(monkeypatch):
    """Kills the bypasses of the shared map: the prediction's writeable flag read from None (always the plain
    route) and the slanted surfaces' call of _bump_fn without its scene (None or dropped: the plain route). The
    pyramids' parallel plane and slanted surfaces of one read-only prediction share one bumpiness map (the
    map computed once), each 8A on its masks."""
    calls = []
    original = region_metrics.bumpiness_map

    def counted(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(region_metrics, "bumpiness_map", counted)
    quarter = np.zeros((N, N), bool)
    quarter[2:6, 2:6] = True
    masks = {("mask_sphere_in", "lowres"): quarter, ("mask_sphere_out", "lowres"): quarter.T[::-1].copy(),
             ("mask_pyramids", "lowres"): np.zeros((N, N), bool)}
    reference = SceneReference(_Scene({"lowres": np.zeros((N, N), F32)}, masks))
    gt = reference.gt("lowres")
    pred = _read_only(_parabola(N))
    plane = np.zeros((N, N), bool)
    plane[6:11, 6:11] = True
    parallel = get_metric("pyramids_bumpiness_parallel")(gt, pred, plane, scene=reference, resolution="lowres")
    slanted = get_metric("pyramids_bumpiness_slanted")(gt, pred, None, scene=reference, resolution="lowres")
    assert parallel == pytest.approx(BUMP, rel=1e-12) and slanted == pytest.approx(BUMP, rel=1e-12)
    assert len(calls) == 1


# --------------------------------------------------------------------------- label values present


def test_present_labels_without_label_0():
    """Kills the OR's starting word 1 (label 0 always present): labels 1 and 3 only."""
    assert _present(np.array([[1, 3], [3, 1]], np.uint8)).tolist() == [False, True, False, True]


def test_present_labels_above_31_are_counted_chunk_by_chunk():
    """Kills the counted branch's class (the range's start, stop and step None, dropped, swapped or 1; the count
    None or of an empty slice; `=`, `&=` for `|=`; `>= 0`, `> 1` for `> 0`): labels 40, 7, 35, 3, 33, 3, 33 in
    chunks of 2 are the values 3, 7, 33, 35, 40 (40 only in the first chunk, 33 last)."""
    labels = np.array([40, 7, 35, 3, 33, 3, 33], np.uint16)
    assert np.flatnonzero(_present(labels, chunk=2)).tolist() == [3, 7, 33, 35, 40]
    assert np.flatnonzero(_present(labels)).tolist() == [3, 7, 33, 35, 40]


def test_present_counts_each_pixel_once_and_only_above_31(monkeypatch):
    """Kills the count's step dropped (a count per pixel of the next chunk-sized slice) and `<` for `<=` at 32
    values: labels 0..31 are ORed as bits, never counted; 7 labels above in chunks of 2 are counted in 4 slices of
    2, 2, 2, 1 pixels."""
    sizes = []
    original = np.bincount

    def counted(x, *args, **kwargs):
        sizes.append(int(np.asarray(x).size))
        return original(x, *args, **kwargs)

    monkeypatch.setattr(np, "bincount", counted)
    assert np.flatnonzero(_present(np.array([31, 5, 5, 31], np.uint8))).tolist() == [5, 31]
    assert sizes == []
    assert np.flatnonzero(_present(np.array([40, 7, 35, 3, 33, 3, 33], np.uint16), chunk=2)).tolist() == [
        3, 7, 33, 35, 40]
    assert sizes == [2, 2, 2, 1]


# --------------------------------------------------------------------------- MAE's ground-truth normals


def test_a_gt_normal_with_any_non_finite_component_is_not_scored():
    """Kills `finite[..., 1]` for `[..., 0]` and `[..., 2]` for `[..., 1]`: four pixels whose gt normals are
    finite, NaN in x, NaN in y, NaN in z, at angles 10, 20, 30, 40 degrees: only the first is scored (median 10;
    15 or 20 if the second or third were)."""
    n_gt = np.tile(np.array([0.0, 0.0, -1.0]), (1, 4, 1))
    for pixel in (1, 2, 3):
        n_gt[0, pixel, pixel - 1] = np.nan
    angle = np.array([[10.0, 20.0, 30.0, 40.0]])
    pred = np.zeros((1, 4), F32)
    assert _median_angle(angle, n_gt, pred, np.ones((1, 4), bool), False) == 10.0


# --------------------------------------------------------------------------- depth_normals' errstate


@pytest.mark.parametrize("scale", [1e160, 1e-85])
def test_depth_normals_of_overflowing_or_underflowing_surfaces_is_silent(scale):
    """Kills depth_normals' `divide` and `over` entries of errstate (None or dropped): a curved surface of depths
    ~1e160 (its cross products overflow: inf / inf) or ~1e-85 (the squared norm underflows to 0: x / 0) gives
    non-finite normals without a RuntimeWarning."""
    rows, cols = np.mgrid[0:5, 0:5].astype(np.float64)
    depth = scale * (2.0 + rows + cols * cols)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        normals = depth_normals(depth, 100.0, 35.0)
    assert not np.isfinite(normals).any()


# --------------------------------------------------------------------------- backgammon: finite half-way values


def test_backgammon_half_way_finiteness_is_kept_per_column():
    """Kills the cache key of the finite half-way values made None (fattening's column-14 flags reused for
    thinning's column 30 - 11 = 19 on one pixel set). Row 0: gt 0, NaN at column 14, pred -1; row 1: gt 0, 1 at
    column 14, pred 0.6. Fattening (pred > (gt + gt[14]) / 2): row 0 not scored, row 1 bad but at column 14
    (0.6 < 1): 29 of 30. Thinning (pred < (gt + gt[19]) / 2 = gt / 2): row 0 scored but at column 14, all bad
    (-1 < 0); row 1 none: 29 of 59."""
    gt = np.zeros((2, 30), F32)
    gt[0, 14] = np.nan
    gt[1, 14] = 1.0
    pred = np.empty((2, 30), F32)
    pred[0], pred[1] = -1.0, 0.6
    px = PixelErrors.of_maps(gt, pred)
    fattening = get_metric("backgammon_fattening").score_pixels(px)
    thinning = get_metric("backgammon_thinning").score_pixels(px)
    assert fattening == pytest.approx(100 * 29 / 30, rel=1e-12)
    assert thinning == pytest.approx(100 * 29 / 59, rel=1e-12)
    px = PixelErrors.of_maps(gt, pred)  # the other order
    assert get_metric("backgammon_thinning").score_pixels(px) == pytest.approx(100 * 29 / 59, rel=1e-12)
    assert get_metric("backgammon_fattening").score_pixels(px) == pytest.approx(100 * 29 / 30, rel=1e-12)


# --------------------------------------------------------------------------- check_maps and protocol_of


def test_check_maps_refusals_word_for_word():
    """Kills check_maps' messages made None: both shapes named, gt and pred's, then the mask's and gt's."""
    with pytest.raises(ValueError) as info:
        check_maps(np.zeros((2, 3)), np.zeros((3, 2)), None)
    assert str(info.value) == "gt (2, 3) and pred (3, 2) differ in shape"
    with pytest.raises(ValueError) as info:
        check_maps(np.zeros((2, 3)), np.zeros((2, 3)), np.ones((2, 2), bool))
    assert str(info.value) == "mask (2, 2) and gt (2, 3) differ in shape"


@pytest.mark.parametrize(("gt_type", "pred_type", "common"), [
    (np.float64, np.float32, np.float64), (np.float32, np.float64, np.float64), (np.float16, np.float16, np.float32),
    (np.uint8, np.uint8, np.float32)])
def test_check_maps_takes_the_common_precision_of_both_at_least_float32(gt_type, pred_type, common):
    """Kills the precision's parts dropped (gt's, pred's or float32): float64 from either map, float32 at least."""
    gt, pred, mask = check_maps(np.ones((2, 2), gt_type), np.ones((2, 2), pred_type), None)
    assert gt.dtype == pred.dtype == common and mask.dtype == bool and mask.all()


def test_protocol_of_a_named_dataset_reads_the_root(tmp_path):
    """Kills protocol_of's name dropped or None (detection instead) and its root None: a TOML dataset's root
    (border 1, as its file says) read by name and by detection; the same root named as HCI is refused."""
    root = tmp_path / "root"
    root.mkdir()
    (root / SPEC_FILE).write_text('[views]\npattern = "v{k}.png"\nangular = 3\nfirst = 1\n'
                                  '[ground_truth]\nfile = "gt.npy"\n[protocol]\nborder = 1\n', encoding="utf-8")
    assert protocol_of(str(root), "toml").border_px == 1
    assert protocol_of(root).border_px == 1
    with pytest.raises(DataError) as info:
        protocol_of(root, "hci")
    assert str(info.value).startswith(f"{root}: not laid out as dataset 'hci' (")
