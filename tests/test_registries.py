"""Tests that follow the registries (as timm's run over list_models()): every registered method runs on a
tiny synthetic scene, every registered metric is checked against a hand-computed case. A method or
metric registered without a way to test it here fails, naming what to add."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from lfbench.data.hci import HCIScene
from lfbench.data.hci.params import SceneParameters
from lfbench.data.pfm import write_pfm
from lfbench.data.scene import Scene
from lfbench.data.synth import generate_scene, write_scene
from lfbench.method.base import Method, content_id
from lfbench.method.registry import create, create_from_spec, format_spec, list_methods, offline_variants
from lfbench.runs.runner import evaluate
from lfbench.scoring.metrics import GENERAL_METRICS, get_metric, list_metrics
from lfbench.scoring.score import score_scene

SIZE = 32  # px: the tiny synthetic scene of the method tests

# --------------------------------------------------------------------------- methods


@pytest.fixture(scope="module")
def synthetic_scene(tmp_path_factory) -> Scene:
    """A 32 x 32 px synthetic light field (lfbench.data.synth) in the HCI layout, with exact gt."""
    folder = tmp_path_factory.mktemp("synth") / "synthetic" / "tiny"
    write_scene(generate_scene(3, size=SIZE, name="tiny"), folder)
    return HCIScene(folder, category="synthetic")


def _published(scene: Scene, tmp: Path) -> tuple[list[Method], np.ndarray | None]:
    """A submission folder the test writes: gt + 0.25 px, so the method must return exactly that map."""
    from lfbench.data.submission import write_submission_map

    expected = (scene.gt_disparity() + np.float32(0.25)).astype(np.float32)
    write_submission_map(tmp / "submission", scene.name, expected, 1.5)
    return [create("published", path=tmp / "submission")], expected


def _lfattnet(scene: Scene, tmp: Path) -> tuple[list[Method], np.ndarray | None]:
    """No checkpoint ships for lfattnet: a small network with fixed random weights (width 4, the
    baseline's interval 1), saved as a checkpoint and run through weights=."""
    import torch
    from lfbench_methods.subfocal.keras_import import save_checkpoint
    from lfbench_methods.subfocal.network import SubFocalNet

    torch.manual_seed(0)
    save_checkpoint(SubFocalNet(interval=1.0, width=4), tmp / "lfattnet_w4.pt", "test: random weights")
    return [create("lfattnet", weights=tmp / "lfattnet_w4.pt", width=4)], None


def _offline(name: str) -> Callable[[Scene, Path], tuple[list[Method], np.ndarray | None]]:
    def make(scene: Scene, tmp: Path) -> tuple[list[Method], np.ndarray | None]:
        return [create(name, **params) for params in offline_variants(name)], None

    return make


def _epinet(scene: Scene, tmp: Path) -> tuple[list[Method], np.ndarray | None]:
    """No checkpoint ships for epinet: a small EPINET (2 filters, 1 merged block) with fixed random weights,
    saved as lfbench train saves weights and run through weights=."""
    import torch
    from lfbench_methods.epinet.network import EPINet

    from lfbench.training.checkpoint import export_weights

    torch.manual_seed(0)
    export_weights(tmp / "epinet_f2.pt", EPINet(filters=2, depth=1), method="epinet")
    return [create("epinet", weights=tmp / "epinet_f2.pt")], None


def _random_network(name: str, **model: object) -> Callable[[Scene, Path], tuple[list[Method], np.ndarray | None]]:
    """No checkpoint ships for the network ``name``: its network of ``model`` with fixed random weights, saved as
    lfbench train saves weights and run through weights=."""
    def make(scene: Scene, tmp: Path) -> tuple[list[Method], np.ndarray | None]:
        import torch

        from lfbench.method.trainable import TRAINABLES
        from lfbench.training.checkpoint import export_weights

        torch.manual_seed(0)
        export_weights(tmp / f"{name}.pt", TRAINABLES.get(name).build(**model), method=name)
        return [create(name, weights=tmp / f"{name}.pt")], None

    return make


#: How the test gets a runnable instance of a method that cannot run from its defaults alone.
PROVIDERS = {"published": _published, "lfattnet": _lfattnet, "epinet": _epinet,
             "distgdisp": _random_network("distgdisp", features=2, channels=4, d_min=-2.0, d_max=2.0),
             "oaccnet": _random_network("oaccnet", d_min=-2.0, d_max=2.0)}


@pytest.mark.parametrize("name", [info.name for info in list_methods()])
def test_every_registered_method_predicts_a_float32_map_of_the_scene(name, synthetic_scene, tmp_path, one_torch_thread):
    methods, expected = PROVIDERS.get(name, _offline(name))(synthetic_scene, tmp_path)
    runnable = [m for m in methods if m.available_for(synthetic_scene) is None]
    if not runnable:
        reasons = "; ".join(str(m.available_for(synthetic_scene)) for m in methods)
        pytest.fail(f"{name} cannot run offline ({reasons}): add a provider to PROVIDERS in {Path(__file__).name}")
    preds = {}
    results = evaluate(runnable, [synthetic_scene], progress=False,
                       on_prediction=lambda m, s, p: preds.setdefault(m.label, p))
    h, w = synthetic_scene.spatial_size
    for method in runnable:
        assert method.name == name and isinstance(method, Method)
        if name == "published":  # names its records after the submission folder
            assert method.label == "published:submission"
        else:  # the label is the canonical spec (a file named by its content), and the spec creates it again
            assert method.label == format_spec(name, {k: content_id(v) if k in method.content_params else v
                                                      for k, v in method.params.items()})
            assert create_from_spec(method.spec).label == method.label
        pred = preds[method.label]
        assert pred.disparity.shape == (h, w) == (SIZE, SIZE) and pred.disparity.dtype == np.float32
        assert np.isfinite(pred.disparity).all()
        if pred.uncertainty is not None:
            assert np.shape(pred.uncertainty) == (h, w) and np.all(np.asarray(pred.uncertainty) >= 0)
        if pred.distribution is not None:
            dist = np.asarray(pred.distribution, dtype=np.float64)
            assert dist.shape == (len(pred.disparity_values), h, w)
            assert np.allclose(dist.sum(axis=0), 1.0, atol=1e-3)
        records = [r for r in results.records if r.method == method.label]
        assert {r.metric for r in records} == {m.id for m in GENERAL_METRICS}
        assert all(r.scene == "tiny" and r.resolution == "lowres" for r in records)
    if name == "gt":
        assert np.array_equal(preds["gt"].disparity, synthetic_scene.gt_disparity())
        assert all(r.value == 0.0 for r in results.records)
    if name == "constant":  # the zero map: hand-computed from the ground truth inside the 15 px border
        assert not preds["constant"].disparity.any()
        gt = synthetic_scene.gt_disparity()[15:-15, 15:-15].astype(np.float64)
        got = {r.metric: r.value for r in results.records}
        assert got["mse_x100"] == pytest.approx(100 * np.mean(gt**2), rel=1e-6)
        assert got["badpix_0.07"] == pytest.approx(100 * np.mean(np.abs(gt) > 0.07), rel=1e-9)
    if expected is not None:
        assert np.array_equal(preds[runnable[0].label].disparity, expected)


# --------------------------------------------------------------------------- metrics

N = 64  # px; the general metrics score the 34 x 34 = 1156 pixels inside the 15 px border
SCORED = 34 * 34
PARAMS = dict(focal_length_mm=100.0, image_resolution_x_px=N, image_resolution_y_px=N, sensor_size_mm=35.0,
              num_cams_x=9, num_cams_y=9, baseline_mm=100.0, focus_distance_m=7.0, disp_min=-1.0, disp_max=1.0)


def _box(y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
    m = np.zeros((N, N), dtype=bool)
    m[y0:y1, x0:x1] = True
    return m


def _scene(root: Path, category: str, name: str, gt: np.ndarray, masks: dict[str, np.ndarray] = {},  # noqa: B006
           labels: dict[str, np.ndarray] = {}) -> Scene:  # noqa: B006
    """A view-less HCI scene: parameters.cfg, gt_disp_lowres.pfm, '<mask>_lowres' PNGs (255 = in)."""
    path = root / category / name
    path.mkdir(parents=True)
    (path / "parameters.cfg").write_text(SceneParameters(**PARAMS, name=name, category=category).to_cfg())
    write_pfm(path / "gt_disp_lowres.pfm", gt.astype(np.float32))
    for key, mask in masks.items():
        Image.fromarray(np.where(mask, 255, 0).astype(np.uint8)).save(path / f"{key}_lowres.png")
    for key, arr in labels.items():
        Image.fromarray(arr.astype(np.uint8)).save(path / f"{key}_lowres.png")
    return HCIScene(path, category=category)


def _general(root: Path) -> tuple[Scene, np.ndarray]:
    """gt 0; inside the border: 100 px off by 0.02, 100 by 0.05, 90 by 0.1, 10 by 1.0, the other 856 by 0.005."""
    gt = np.zeros((N, N), np.float32)
    pred = np.full((N, N), 0.005, np.float32)
    inner = np.full(SCORED, 0.005, np.float32)
    inner[:100], inner[100:200], inner[200:290], inner[290:300] = 0.02, 0.05, 0.1, 1.0
    pred[15:49, 15:49] = inner.reshape(34, 34)
    return _scene(root, "training", "toy", gt), pred


_ERR2 = 100 * 0.02**2 + 100 * 0.05**2 + 90 * 0.1**2 + 10 * 1.0**2 + 856 * 0.005**2


def _parabola(a: float) -> np.ndarray:
    """pred - gt = a y^2 / 2: the Scharr Hessian reads 4a everywhere, bumpiness 100 min(4a, 0.05)."""
    y = np.mgrid[0:N, 0:N][0].astype(np.float64)
    return (0.5 * a * y * y).astype(np.float32)


def _bumpiness(mask: str, a: float, category: str = "training", name: str = "toy"):
    def case(root: Path) -> tuple[Scene, np.ndarray, float]:
        return _scene(root, category, name, np.zeros((N, N), np.float32), {mask: _box(20, 44, 20, 44)}), \
            _parabola(a), 100 * min(4 * a, 0.05)
    return case


def _mae(mask: str, degrees: float):
    """gt: a fronto-parallel plane at 2 m; pred: the 3D plane through it tilted by ``degrees`` about the
    vertical axis. Every finite-difference tangent of a plane lies in the plane, so each normal is the
    plane's own and the angle is exactly ``degrees`` (up to float32 storage of the disparities)."""
    def case(root: Path) -> tuple[Scene, np.ndarray, float]:
        p = SceneParameters(**PARAMS)
        z0, t = 2.0, math.tan(math.radians(degrees))
        a = 0.5 * p.sensor_size_mm / p.focal_length_mm / (N - 1)  # X = a * col * Z (the toolkit's camera model)
        col = np.mgrid[0:N, 0:N][1].astype(np.float64)
        gt = p.depth_to_disparity(np.full((N, N), z0)).astype(np.float32)
        pred = p.depth_to_disparity(z0 / (1.0 - t * a * col)).astype(np.float32)  # Z = z0 + t X
        return _scene(root, "training", "toy", gt, {mask: _box(20, 44, 20, 44)}), pred, degrees
    return case


def _badpix_on(mask: str, category: str, name: str, bad: int):
    """A 10 x 10 mask; ``bad`` of its pixels off by 0.1 px (> 0.07), the others by 0.05."""
    def case(root: Path) -> tuple[Scene, np.ndarray, float]:
        pred = np.full((N, N), 0.05, np.float32)
        block = np.full(100, 0.05, np.float32)
        block[:bad] = 0.1
        pred[20:30, 20:30] = block.reshape(10, 10)
        return _scene(root, category, name, np.zeros((N, N), np.float32), {mask: _box(20, 30, 20, 30)}), pred, \
            100.0 * bad / 100
    return case


def _fine(mask: str, offset: float, bad: int):
    def case(root: Path) -> tuple[Scene, np.ndarray, float]:
        pred = np.zeros((N, N), np.float32)
        pred[20:20 + bad // 10, 20:30] = offset  # gt - pred = -offset
        return _scene(root, "training", "toy", np.zeros((N, N), np.float32), {mask: _box(20, 30, 20, 30)}), pred, \
            float(bad)
    return case


def _backgammon(root: Path) -> tuple[Scene, np.ndarray]:
    gt = np.zeros((N, N), np.float32)
    gt[:, 10:30] = 1.0  # a foreground bar over column 14; column 64 - 11 = 53 is background (0)
    scene = _scene(root, "stratified", "backgammon", gt, {
        "mask_foreground_fattening": _box(20, 40, 30, 35),  # 100 background px next to the bar
        "mask_foreground_thinning": _box(20, 40, 20, 30)})  # 200 bar px
    pred = gt.copy()
    pred[20:40, 30:32] = 0.6  # 40 px nearer to the foreground than half way (0.5): fattening 40 %
    pred[20:30, 20:25] = 0.4  # 50 bar px nearer to the background than half way: thinning 25 %
    return scene, pred


def _dots(root: Path) -> tuple[Scene, np.ndarray]:
    gt = np.full((N, N), 0.3, np.float32)
    boxes = np.zeros((N, N), np.uint8)
    boxes[16:32, 16:48], boxes[32:48, 16:48] = 1, 2
    dots = np.zeros((N, N), np.uint8)
    for top in (18, 34):  # 3 dots per box: 6 dots
        dots[top:top + 4, 18:22], dots[top:top + 3, 26:29], dots[top:top + 2, 36:38] = 1, 2, 3
    background = (boxes > 0) & (dots == 0)
    scene = _scene(root, "stratified", "dots", gt, {"mask_background": background},
                   {"mask_boxes": boxes, "mask_dots_by_size": dots})
    pred = gt.copy()
    pred[34:37, 26:29] = 1.0  # one dot entirely off by 0.7 px: 1 of 6 missed
    pred[background] += np.float32(0.1)  # background error 0.1 px: MSE x100 = 1
    return scene, pred


def _slanted(root: Path) -> tuple[Scene, np.ndarray, float]:
    masks = {"mask_sphere_in": _box(20, 30, 20, 30), "mask_sphere_out": _box(30, 40, 30, 40),
             "mask_pyramids": _box(40, 45, 40, 45), "mask_plane": _box(15, 49, 15, 49)}
    return _scene(root, "stratified", "pyramids", np.zeros((N, N), np.float32), masks), _parabola(0.0025), 1.0


#: metric id -> case(tmp_path) -> (scene, prediction, the value worked out by hand)
CASES: dict[str, Callable[[Path], tuple[Scene, np.ndarray, float]]] = {
    "badpix_0.01": lambda r: (*_general(r), 100.0 * 300 / SCORED),
    "badpix_0.03": lambda r: (*_general(r), 100.0 * 200 / SCORED),
    "badpix_0.07": lambda r: (*_general(r), 100.0 * 100 / SCORED),
    "badpix_0.5": lambda r: (*_general(r), 100.0 * 10 / SCORED),  # the badpix_<t> family
    "mse_x100": lambda r: (*_general(r), 100.0 * _ERR2 / SCORED),
    "q25_x100": lambda r: (*_general(r), 0.5),  # index int(0.25 * 1156) = 289 of the sorted errors: 0.005 px
    # the q<p>_x100 family: index int(0.9 * 1156) = 1040 lies in the 100 errors of 0.05 px (sorted 956..1055)
    "q90_x100": lambda r: (*_general(r), 5.0),
    # runtime metrics: the runtime the method reports (RUNTIME_S), not the maps
    "runtime": lambda r: (*_general(r), RUNTIME_S),
    "runtime_log": lambda r: (*_general(r), math.log10(RUNTIME_S)),
    "discontinuities": _badpix_on("mask_discontinuities", "training", "toy", 30),
    "bumpiness_planes": _bumpiness("mask_planes", 0.005),
    "bumpiness_contin_surfaces": _bumpiness("mask_smooth_surfaces", 0.02),  # 4a = 0.08 is clipped to 0.05
    "mae_planes": _mae("mask_planes", 45.0),
    "mae_contin_surfaces": _mae("mask_smooth_surfaces", 30.0),
    "fine_fattening": _fine("mask_fine_surrounding", 0.2, 40),
    "fine_thinning": _fine("mask_fine", -0.2, 70),
    "backgammon_fattening": lambda r: (*_backgammon(r), 40.0),
    "backgammon_thinning": lambda r: (*_backgammon(r), 25.0),
    "dots_background_mse": lambda r: (*_dots(r), 1.0),
    "missed_dots": lambda r: (*_dots(r), 100.0 / 6),
    "pyramids_bumpiness_slanted": _slanted,
    "pyramids_bumpiness_parallel": _bumpiness("mask_plane", 0.005, "stratified", "pyramids"),
    "stripes_low_texture": _badpix_on("mask_low_texture", "stratified", "stripes", 10),
    "stripes_dark": _badpix_on("mask_high_contrast", "stratified", "stripes", 20),
    "stripes_bright": _badpix_on("mask_low_contrast", "stratified", "stripes", 45),
}


RUNTIME_S = 2.5  # the runtime every case's method reports (s)


@pytest.mark.parametrize("metric_id", [m.id for m in list_metrics()] + ["badpix_0.5", "q90_x100"])
def test_every_registered_metric_against_a_hand_computed_case(metric_id, tmp_path):
    if metric_id not in CASES:
        pytest.fail(f"metric {metric_id} has no hand-computed case: add one to CASES in {Path(__file__).name}")
    metric = get_metric(metric_id)
    scene, pred, expected = CASES[metric_id](tmp_path)
    score = score_scene(scene, pred, [metric], runtime_s=RUNTIME_S)
    assert metric_id in score.values, f"{metric_id} did not apply to its case"
    assert score.resolution[metric_id] == "lowres"
    if metric.unit.startswith("%"):  # a count over a count: no rounding beyond the division
        assert score.values[metric_id] == pytest.approx(expected, rel=1e-12)
    else:  # float32 disparities (and depth round trips for MAE)
        assert score.values[metric_id] == pytest.approx(expected, rel=1e-4, abs=1e-4)
