"""The synthetic light-field generator (lfbench.data.synth, `lfbench synth`): determinism, the benchmark's
geometry (warping views by the ground truth reproduces the centre view; the wrong sign does not),
analytic ground truth of planes and quadrics, the cfg's depth <-> disparity, the HCI layout as read
by lfbench.data.scene, atomic writing and the CLI."""

from __future__ import annotations

import configparser
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import run_cli
from scipy import ndimage

from lfbench.data import synth
from lfbench.data.hci import HCIDataset, HCIScene
from lfbench.data.hci.params import read_parameters
from lfbench.data.pfm import read_pfm
from lfbench.data.scene import rgb_to_gray
from lfbench.data.synth import Affine, Quadric, generate_scene, quantize, view_offsets, write_benchmark
from lfbench.data.urbanlf import URBANLF_DISPARITY_RANGE
from lfbench.scoring.score import score_scene
from lfbench.utils.errors import SpecError

SIZE = 64


@pytest.fixture(scope="module")
def scene() -> synth.SyntheticScene:
    return generate_scene(5, size=SIZE)


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> tuple[Path, list[Path]]:
    root = tmp_path_factory.mktemp("synth")
    return root, write_benchmark(root, seed=7, size=48, scenes=2)


def files_of(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def warp_to_centre(gray: np.ndarray, disparity: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """Every view (A, A, H, W) bilinearly sampled at (x - sign (u-c) d, y - sign (v-c) d): (A*A, H, W).

    Written independently of the renderer: plain bilinear interpolation, clamped at the border.
    """
    a, _, h, w = gray.shape
    c = a // 2
    k = np.arange(a * a)
    su, sv = (k % a - c)[:, None, None], (k // a - c)[:, None, None]
    yy, xx = np.mgrid[0:h, 0:w]
    x = np.clip(xx - sign * su * disparity, 0, w - 1.0001)
    y = np.clip(yy - sign * sv * disparity, 0, h - 1.0001)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    flat = gray.reshape(a * a, h * w)

    def at(yi, xi):
        return np.take_along_axis(flat, (yi * w + xi).reshape(a * a, -1), axis=1).reshape(a * a, h, w)

    return ((at(y0, x0) * (1 - fx) + at(y0, x0 + 1) * fx) * (1 - fy)
            + (at(y0 + 1, x0) * (1 - fx) + at(y0 + 1, x0 + 1) * fx) * fy)


def seen_in_both(sc: synth.SyntheticScene) -> np.ndarray:
    """(A*A, H, W): centre pixels whose point is seen in view k, 2 px away from any pixel that is not,
    and off the discontinuity mask (the bilinear footprint then lies on one surface)."""
    vis = sc.visibility().reshape(-1, *sc.disparity.shape)
    vis = ndimage.binary_erosion(vis, structure=np.ones((1, 3, 3), bool), iterations=2)
    return vis & ~sc.masks["mask_discontinuities"]


# --------------------------------------------------------------------------- determinism


def test_same_seed_gives_identical_bytes_and_another_seed_differs(tmp_path, written):
    root, paths = written
    again = write_benchmark(tmp_path / "again", seed=7, size=48, scenes=2)
    for a, b in zip(paths, again, strict=True):
        assert files_of(a) == files_of(b)
    other = write_benchmark(tmp_path / "other", seed=8, size=48, scenes=1)[0]
    a, b = files_of(paths[0]), files_of(other)
    assert a.keys() == b.keys()
    assert a["input_Cam040.png"] != b["input_Cam040.png"]
    assert a["gt_disp_lowres.pfm"] != b["gt_disp_lowres.pfm"]
    # scenes of one benchmark differ from each other, too
    assert files_of(paths[0])["gt_disp_lowres.pfm"] != files_of(paths[1])["gt_disp_lowres.pfm"]


def test_scenes_generated_in_parallel_are_the_same_files(tmp_path, written):
    _, paths = written
    parallel = write_benchmark(tmp_path / "parallel", seed=7, size=48, scenes=2, workers=2)
    assert [p.name for p in parallel] == [p.name for p in paths]
    for a, b in zip(paths, parallel, strict=True):
        assert files_of(a) == files_of(b)
    assert not [p for p in (tmp_path / "parallel" / "synthetic").iterdir() if p.name.startswith(".")]
    with pytest.raises(SpecError, match="workers"):
        write_benchmark(tmp_path / "bad", seed=7, size=48, scenes=1, workers=0)


def test_generate_scene_is_deterministic_in_memory(scene):
    again = generate_scene(5, size=SIZE)
    assert np.array_equal(again.views, scene.views)
    assert np.array_equal(again.disparity, scene.disparity)
    assert not np.array_equal(generate_scene(6, size=SIZE).disparity, scene.disparity)


# --------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("seed", [5, 11])
def test_views_warped_by_ground_truth_reproduce_the_centre_view(seed, scene):
    sc = scene if seed == 5 else generate_scene(seed, size=SIZE)
    # as written to disk: 8-bit, then the benchmark's gray
    gray = rgb_to_gray(quantize(sc.views).astype(np.float32) / 255.0)
    a = gray.shape[0]
    centre = gray[a // 2, a // 2]
    visible = seen_in_both(sc)
    assert visible.sum() > 0.15 * visible.size
    right = np.abs(warp_to_centre(gray, sc.disparity) - centre)[visible]
    wrong = np.abs(warp_to_centre(gray, sc.disparity, sign=-1.0) - centre)[visible]
    assert np.median(right) < 0.01
    assert np.percentile(right, 90) < 0.04
    assert np.median(wrong) > 3 * np.median(right) and np.median(wrong) > 0.02
    # pixels hidden in some view do not match there: visibility is not trivially everything
    hidden = ~sc.visibility().all(axis=(0, 1))
    hidden[:12], hidden[-12:], hidden[:, :12], hidden[:, -12:] = False, False, False, False  # image borders
    assert hidden.sum() > 50


def test_a_disparity_range_maps_the_same_scene_into_it(scene):
    """``disparity_range`` (issue 30: UrbanLF-Syn's [-0.47, 1.55] px) moves every surface to scale * d +
    offset: the same layer at every pixel, the ground truth mapped exactly and within the range, the views
    still matching it (warped by it, they reproduce the centre view); None is the generator's own scene."""
    lo, hi = URBANLF_DISPARITY_RANGE
    sc = generate_scene(5, size=SIZE, disparity_range=(lo, hi))
    scale, offset = synth.disparity_map((lo, hi))
    assert 0 < scale < 1
    np.testing.assert_array_equal(sc.layer_id, scene.layer_id)
    np.testing.assert_allclose(sc.disparity, scale * scene.disparity.astype(np.float64) + offset, atol=1e-5)
    assert lo <= sc.disparity.min() < sc.disparity.max() <= hi
    assert sc.disparity.max() - sc.disparity.min() > 0.6 * (hi - lo)  # spread over the range, not squeezed
    gray = rgb_to_gray(quantize(sc.views).astype(np.float32) / 255.0)
    visible = seen_in_both(sc)
    right = np.abs(warp_to_centre(gray, sc.disparity) - gray[4, 4])[visible]
    assert np.median(right) < 0.01 and np.percentile(right, 90) < 0.04
    own = generate_scene(5, size=SIZE, disparity_range=None)
    assert np.array_equal(own.views, scene.views) and np.array_equal(own.disparity, scene.disparity)


@pytest.mark.parametrize("bad", [(1.0, 1.0), (2.0, -2.0), (float("nan"), 1.0), (-3.0, 2.0), (-3.6, -3.0)])
def test_an_impossible_disparity_range_is_refused(bad):
    with pytest.raises(SpecError, match="disparity range"):
        generate_scene(5, size=16, disparity_range=bad)


def test_inverse_map_inverts_the_forward_projection(scene):
    """p -> x' = p - s d(p) (the benchmark's projection) followed by the layer's inverse map gives p back,
    for every layer (planes in closed form, quadrics by Newton iteration) and every view."""
    rng = np.random.default_rng(0)
    su, sv = view_offsets(9)
    su, sv = su.astype(np.float64)[:, None], sv.astype(np.float64)[:, None]
    kinds = set()
    for layer in scene.layers:
        x0, y0, x1, y1 = layer.bbox
        px, py = rng.uniform(max(x0, -8), min(x1, SIZE + 8), 400), rng.uniform(max(y0, -8), min(y1, SIZE + 8), 400)
        inside = layer.shape.contains(px, py)
        px, py = px[inside][None], py[inside][None]
        d = layer.surface.disparity(px, py)
        qx, qy, dq, hit = layer.solve(px - su * d, py - sv * d, su, sv)
        assert hit.all(), layer.name
        assert np.abs(qx - px).max() < 1e-6 and np.abs(qy - py).max() < 1e-6, layer.name
        assert np.allclose(dq, d, atol=1e-8)
        kinds.add(type(layer.surface).__name__)
    assert kinds == {"Affine", "Quadric"}


def test_renderer_matches_a_scalar_reference_on_sampled_pixels(scene):
    """Vectorised z-buffer (crops, packed atlas) against a direct evaluation of a few pixels: every layer
    solved at the pixel's 2x2 samples, the largest disparity wins; a pixel inside one layer takes the
    texture at its samples' mean surface point, a pixel across an edge averages its samples' colours."""
    rng = np.random.default_rng(1)
    ss = synth.SUPERSAMPLE
    offsets = (np.arange(ss) + 0.5) / ss - 0.5
    a = scene.views.shape[0]
    c = a // 2
    checked = 0
    for _ in range(300):
        v, u = rng.choice([0, 1, a // 2, a - 2, a - 1], 2)  # mostly outer views: the largest shifts
        y, x = rng.integers(0, SIZE, 2)
        sx, sy = np.meshgrid(x + offsets, y + offsets)
        sx, sy = sx.ravel().astype(np.float64), sy.ravel().astype(np.float64)
        best = np.full(sx.size, -np.inf)
        owner = np.full(sx.size, -1)
        pts = np.zeros((sx.size, 2))
        for i, layer in enumerate(scene.layers):
            px, py, d, hit = layer.solve(sx, sy, float(u - c), float(v - c))
            win = hit & (d > best)
            best[win], owner[win], pts[win] = d[win], i, np.stack([px, py], 1)[win]
        if (owner == owner[0]).all():
            mean = pts.mean(axis=0)
            ref = scene.layers[owner[0]].texture.sample(mean[:1], mean[1:])[0]
        else:
            ref = np.mean([scene.layers[o].texture.sample(p[:1], p[1:])[0] for o, p in zip(owner, pts, strict=True)],
                          axis=0)
        np.testing.assert_allclose(scene.views[v, u, y, x], ref, atol=2e-4)
        checked += 1
    assert checked == 300


# --------------------------------------------------------------------------- analytic ground truth


def _interior(mask: np.ndarray, r: int = 2) -> np.ndarray:
    return ndimage.binary_erosion(mask, iterations=r)


def test_planes_and_quadrics_have_their_analytic_disparity(scene):
    """Slanted planes: finite differences of the ground truth equal the plane's gradient, second
    differences vanish. Quadric caps d0 + h (1 - r^2/R^2): the 5-point Laplacian is exactly -4 h / R^2
    (a cylinder: -2 h / R^2), so the surfaces are really curved and the ground truth is exact."""
    d = scene.disparity.astype(np.float64)
    dx, dy = np.diff(d, axis=1)[1:-1, :-1], np.diff(d, axis=0)[:-1, 1:-1]
    lap = d[:-2, 1:-1] + d[2:, 1:-1] + d[1:-1, :-2] + d[1:-1, 2:] - 4 * d[1:-1, 1:-1]
    found = {"slanted": 0, "curved": 0}
    for i, layer in enumerate(scene.layers):
        own = _interior(scene.layer_id == i)[1:-1, 1:-1]
        if own.sum() < 10:
            continue
        surf = layer.surface
        if isinstance(surf, Affine) and surf.max_slope() > 1e-3:
            np.testing.assert_allclose(dx[own], surf.gx, atol=2e-5)
            np.testing.assert_allclose(dy[own], surf.gy, atol=2e-5)
            np.testing.assert_allclose(lap[own], 0.0, atol=5e-5)
            found["slanted"] += 1
        elif isinstance(surf, Quadric):
            yy, xx = np.mgrid[1:SIZE - 1, 1:SIZE - 1]
            rho = (np.hypot(xx - surf.cx, yy - surf.cy) if surf.axis is None
                   else np.abs(surf.axis[0] * (xx - surf.cx) + surf.axis[1] * (yy - surf.cy)))
            core = own & (rho < surf.radius - 2)
            expected = (-4.0 if surf.axis is None else -2.0) * surf.h / surf.radius**2
            if core.sum() >= 5:
                np.testing.assert_allclose(lap[core], expected, atol=5e-5)
                assert abs(expected) > 1e-3
                found["curved"] += 1
    assert found["slanted"] >= 2 and found["curved"] >= 1, found  # background and slanted_plane are slanted


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_scene_content_occlusions_fine_structures_and_contrast(seed):
    sc = generate_scene(seed, size=SIZE)
    d = sc.disparity
    assert -3.0 <= d.min() and d.max() <= 3.0
    assert max(np.abs(np.diff(d, axis=0)).max(), np.abs(np.diff(d, axis=1)).max()) > 1.0  # depth edges
    assert {layer.region for layer in sc.layers} == {"plane", "smooth", "fine"}
    names = {sc.layers[i].name for i in np.unique(sc.layer_id)}
    assert "background" in names and any(n.startswith("bar") for n in names)
    for name in synth.MASK_NAMES:
        assert sc.masks[name].shape == d.shape and sc.masks[name].dtype == bool
    for name in ("mask_discontinuities", "mask_planes", "mask_fine", "mask_fine_surrounding"):
        assert sc.masks[name].any(), name
    assert not (sc.masks["mask_planes"] & sc.masks["mask_discontinuities"]).any()
    assert not (sc.masks["mask_fine"] & sc.masks["mask_fine_surrounding"]).any()
    # contrast varies: the low-texture panel is nearly flat, the wall is strongly textured
    gray = sc.gray_views()[4, 4]
    contrasts = {layer.name: layer.texture.contrast for layer in sc.layers}
    assert contrasts["low_texture_panel"] < 0.02 and contrasts["wall"] > 0.25
    low = sc.masks["mask_low_texture"]
    if low.sum() > 20:
        wall = _interior(sc.layer_id == [ly.name for ly in sc.layers].index("wall"))
        assert gray[low].std() < 0.5 * gray[wall].std()


# --------------------------------------------------------------------------- files


def test_written_scene_loads_in_the_hci_layout(written):
    root, paths = written
    bench = HCIDataset.open(root)
    assert sorted(s.name for s in bench) == ["synth_7_0", "synth_7_1"]
    assert {s.category for s in bench} == {"synthetic"}
    for path in paths:
        sc = HCIScene(path)
        params = sc.params
        seed = int(params.extra["meta"]["synth_seed"])
        ref = generate_scene(seed, size=48, name=path.name)
        assert sc.angular_size == (9, 9) and sc.spatial_size == (48, 48)
        assert params.name == path.name and params.category == "synthetic"
        np.testing.assert_allclose(sc.rgb_views(), ref.views, atol=0.5 / 255 + 1e-6)
        assert np.array_equal(sc.gt_disparity(), ref.disparity)
        assert set(sc.mask_names()) == set(synth.MASK_NAMES)
        for name in synth.MASK_NAMES:
            assert np.array_equal(sc.mask(name), ref.masks[name]), name
        assert params.disp_min <= ref.disparity.min() and ref.disparity.max() <= params.disp_max
        assert params.disp_max - params.disp_min < ref.disparity.max() - ref.disparity.min() + 0.21
        # the harness scores the ground truth as perfect
        score = score_scene(sc, sc.gt_disparity())
        assert score.values["badpix_0.07"] == 0.0 and score.values["mse_x100"] == 0.0


def test_depth_and_disparity_round_trip_through_parameters_cfg(written):
    _, paths = written
    for path in paths:
        disp = read_pfm(path / "gt_disp_lowres.pfm")
        depth = read_pfm(path / "gt_depth_lowres.pfm")
        assert depth.dtype == np.float32 and np.isfinite(depth).all() and (depth > 0).all()
        # by hand from the cfg: d = b f N / s (1/Z - 1/F), b in m
        cfg = configparser.ConfigParser()
        cfg.read(path / "parameters.cfg")
        b = cfg.getfloat("extrinsics", "baseline_mm") / 1000
        f = cfg.getfloat("intrinsics", "focal_length_mm")
        s = cfg.getfloat("intrinsics", "sensor_size_mm")
        n = max(cfg.getint("intrinsics", "image_resolution_x_px"), cfg.getint("intrinsics", "image_resolution_y_px"))
        focus = cfg.getfloat("extrinsics", "focus_distance_m")
        by_hand = b * f * n / s * (1 / depth.astype(np.float64) - 1 / focus)
        np.testing.assert_allclose(by_hand, disp, atol=1e-4)
        params = read_parameters(path / "parameters.cfg")
        np.testing.assert_allclose(params.depth_to_disparity(depth), disp, atol=1e-4)
        np.testing.assert_allclose(params.disparity_to_depth(disp), depth, rtol=1e-6)
        # closer (larger disparity) is nearer
        order = np.argsort(disp.ravel())
        assert depth.ravel()[order[0]] > depth.ravel()[order[-1]]


def test_interrupted_write_leaves_nothing(tmp_path, monkeypatch):
    def boom(*args, **kwargs):
        raise OSError("disk full")

    import lfbench.data.hci.write as hci_write

    monkeypatch.setattr(hci_write, "write_pfm", boom)  # the HCI writer fails half-way through the scene
    with pytest.raises(OSError):
        write_benchmark(tmp_path, seed=1, size=32, scenes=1)
    leftovers = [p for p in tmp_path.rglob("*") if p.is_file() or p.name.startswith(".")]
    assert leftovers == [] and not (tmp_path / "synthetic" / "synth_1_0").exists()


def test_per_scene_categories_and_force(tmp_path):
    paths = write_benchmark(tmp_path, seed=2, size=32, scenes=2, category=["additional", "stratified"])
    assert [p.relative_to(tmp_path).as_posix() for p in paths] == ["additional/synth_2_0", "stratified/synth_2_1"]
    bench = HCIDataset.open(tmp_path)
    assert [s.category for s in bench.split("train")] == ["additional"]
    with pytest.raises(synth.DataError, match="already exists"):
        write_benchmark(tmp_path, seed=2, size=32, scenes=2, category=["additional", "stratified"])
    marker = paths[0] / "stale.txt"
    marker.write_text("old")
    write_benchmark(tmp_path, seed=2, size=32, scenes=1, category="additional", force=True)
    assert not marker.exists() and (paths[0] / "input_Cam080.png").is_file()
    assert not [p for p in (tmp_path / "additional").iterdir() if p.name.startswith(".")]
    with pytest.raises(synth.SpecError):
        write_benchmark(tmp_path, scenes=2, category=["a"])


# --------------------------------------------------------------------------- CLI


def test_cli_writes_refuses_to_overwrite_and_forces(tmp_path, capsys):
    rc, out, err = run_cli(capsys, "synth", "--out", tmp_path, "--seed", 3, "--size", 32, "--scenes", 2,
                           "--no-progress")
    assert rc == 0, err
    folders = sorted((tmp_path / "synthetic").iterdir())
    assert [p.name for p in folders] == ["synth_3_0", "synth_3_1"]
    assert len(list(folders[0].glob("input_Cam*.png"))) == 81
    before = files_of(folders[0])
    rc, out, err = run_cli(capsys, "synth", "--out", tmp_path, "--seed", 3, "--size", 32, "--scenes", 1)
    assert rc == 2 and len(err.splitlines()) == 1 and "already exists" in err and "Traceback" not in err
    rc, _, err = run_cli(capsys, "synth", "--out", tmp_path, "--seed", 3, "--size", 32, "--scenes", 1, "--force",
                         "--no-progress")
    assert rc == 0, err
    assert files_of(folders[0]) == before  # deterministic: the same bytes again
    rc, _, err = run_cli(capsys, "synth", "--out", tmp_path, "--category", "mine", "--size", 32, "--scenes", 1,
                         "--no-progress")
    assert rc == 0 and (tmp_path / "mine" / "synth_0_0" / "parameters.cfg").is_file()


@pytest.mark.parametrize("args", [["--size", "8"], ["--angular", "4"], ["--scenes", "0"], ["--category", "a/b"]])
def test_cli_bad_options_exit_2_with_one_line(tmp_path, capsys, args):
    rc, _, err = run_cli(capsys, "synth", "--out", tmp_path, "--no-progress", *args)
    assert rc == 2 and len(err.splitlines()) == 1 and "Traceback" not in err
    assert not any(tmp_path.iterdir())


def test_small_angular_grid_keeps_the_geometry():
    sc = generate_scene(4, size=40, angular=5)
    assert sc.views.shape == (5, 5, 40, 40, 3) and sc.params.angular_size == (5, 5)
    gray = sc.gray_views()
    err = np.abs(warp_to_centre(gray, sc.disparity) - gray[2, 2])[seen_in_both(sc)]
    assert np.median(err) < 0.01
    assert math.isclose(sc.params.baseline_mm, 100.0 * 512 / 40)
