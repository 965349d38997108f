"""Training and validation data: scenes held in memory and the authors' patch sampler.

A training scene is kept as uint8 RGB (H, W, N, 3) (N = V * U views, view k = v * U + u), its
disparity (H, W) float32 in px per view step, and an optional mask (H, W) of pixels a patch may
not touch. The sampler draws P x P patches with a P x P label:

- scene by weight (the authors: kitchen, museum, vinyl once, the others 4 times);
- stride s in ``strides`` by ``stride_weights`` (8/17, 6/17, 3/17 for 1, 2, 3): the patch is
  taken every s px and its label divided by s; the start is uniform over all positions where
  the strided patch fits;
- random gray weights 0.05 + U(0, 1) per channel, normalised to sum 1 (or the fixed ones);
- rejection: resampled until sum |centre - centre[P//2, P//2]| >= texture * P^2 on the gray
  centre view, and no pixel of the strided patch is masked;
- then the augmentation of lfbench.training.augment.

Determinism: sample i of the global batch of step t in stage k is a pure function of
(seed, k, t, i): it draws from its own ``numpy.random.default_rng([seed, k, t, i])``. A run
resumed from a checkpoint, a run on several processes (each takes its slice of the global
batch) and a single-process run therefore see exactly the same samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfbench.data.scene import GRAY_WEIGHTS, Scene, read_png
from lfbench.training.augment import apply_augment, draw_augment
from lfbench.training.config import AugmentConfig, DataConfig
from lfbench.utils.errors import DataError

MAX_ROUNDS = 2000  # rejection rounds per sample before giving up


@dataclass
class SceneData:
    """One training scene in memory."""

    name: str
    rgb: np.ndarray  # (H, W, N, 3) uint8
    disparity: np.ndarray  # (H, W) float32, px per view step
    blocked: np.ndarray | None  # (H, W) bool: True = no patch may contain this pixel
    angular: tuple[int, int]  # (V, U)

    @property
    def shape(self) -> tuple[int, int]:
        return self.rgb.shape[0], self.rgb.shape[1]


def read_views_uint8(scene: Scene) -> np.ndarray:
    """All views of a scene of any storage as uint8 RGB (H, W, N, 3), view k = angular row k // U, column k % U,
    read through the scene's adapter (:meth:`lfbench.data.scene.Scene.views_uint8`)."""
    v, u = scene.angular_size
    views = scene.views_uint8()  # (V, U, H, W, 3)
    h, w = views.shape[2:4]
    return np.ascontiguousarray(np.moveaxis(views.reshape(v * u, h, w, 3), 0, 2))


def read_invalid_area(path: Path) -> np.ndarray:
    """The authors' invalid-area PNG as bool (H, W): alpha > 0 (any channel > 0 without alpha)."""
    arr = read_png(path, "invalid-area mask")
    if arr.ndim == 3:
        return arr[..., 3] > 0 if arr.shape[2] == 4 else arr.any(axis=-1)
    return arr > 0


def load_scene_data(scene: Scene, invalid_area: Path | None = None) -> SceneData:
    """Read a training scene: views, low-res ground truth and the pixels patches must avoid.

    Blocked pixels: False in the scene's valid mask, alpha > 0 in ``<invalid_area>/<scene>/<file>`` (the file
    its layout names: ``scene.invalid_area_file``, HCI's ``input_Cam040_invalid_ver2.png``), and non-finite
    ground truth.
    """
    gt = scene.gt_disparity()
    if gt is None:
        raise DataError("training scene has no ground truth disparity", scene.path)
    gt = np.asarray(gt, dtype=np.float32)
    blocked = ~np.isfinite(gt)
    valid = scene.valid_mask()  # refused unless the scene's size
    if valid is not None:
        blocked |= ~valid
    if invalid_area is not None and scene.invalid_area_file is not None:
        path = invalid_area / scene.name / scene.invalid_area_file
        if path.is_file():
            mask = read_invalid_area(path)
            if mask.shape != gt.shape:
                raise DataError(f"mask is {mask.shape[1]}x{mask.shape[0]}, expected {gt.shape[1]}x{gt.shape[0]}",
                                path)
            blocked |= mask
    return SceneData(name=scene.name, rgb=read_views_uint8(scene), disparity=np.where(blocked, 0.0, gt).astype(
        np.float32), blocked=blocked if blocked.any() else None, angular=scene.angular_size)


def scene_probabilities(names: Sequence[str], default: float, overrides: dict[str, float]) -> np.ndarray:
    """Sampling probabilities (S,) from per-name weights (``default`` for names not overridden)."""
    w = np.array([float(overrides.get(n, default)) for n in names], dtype=np.float64)
    if not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
        given = dict(zip(names, w.tolist(), strict=True))
        raise DataError(f"scene sampling weights must be >= 0 and not all 0, got {given}")
    return w / w.sum()


def sample_rng(seed: int, stage: int, step: int, index: int) -> np.random.Generator:
    """The generator of sample ``index`` of the global batch of ``step`` in ``stage``."""
    return np.random.default_rng([seed, stage, step, index])


class PatchSampler:
    """Draws augmented training patches; see the module docstring for the procedure.

    ``sample(seed, stage, step, start, count)`` returns views (count, N, P, P) float32 in [0, 1]
    (channel k = view k) and labels (count, P, P) float32, for samples start..start+count-1 of
    the step's global batch.
    """

    def __init__(self, scenes: Sequence[SceneData], data: DataConfig, augment: AugmentConfig,
                 candidates: int = 4) -> None:
        if not scenes:
            raise DataError("no training scenes")
        angular = {s.angular for s in scenes}
        if len(angular) != 1:
            raise DataError(f"training scenes differ in angular size: {sorted(angular)}")
        self.angular = angular.pop()
        self.scenes = list(scenes)
        self.patch = data.patch
        self.strides = np.asarray(data.strides, dtype=np.int64)
        sw = np.asarray(data.stride_weights, dtype=np.float64)
        self.stride_p = sw / sw.sum()
        self.scene_p = scene_probabilities([s.name for s in scenes], data.default_scene_weight, data.scene_weights)
        self.texture = data.texture
        self.random_gray = data.random_gray
        self.augment = augment
        self.candidates = candidates
        v, u = self.angular
        self.centre = (v // 2) * u + u // 2
        p = self.patch
        fits = [s.shape[0] >= p and s.shape[1] >= p for s in scenes]
        if not all(fits):
            small = [s.name for s, ok in zip(scenes, fits, strict=True) if not ok]
            raise DataError(f"scenes smaller than the {p}x{p} patch: {', '.join(small)}")
        self.sizes = np.array([s.shape for s in scenes], dtype=np.int64)  # (S, 2)

    # -- candidates ------------------------------------------------------------------------------

    def _draw(self, rng: np.random.Generator, k: int) -> dict[str, np.ndarray]:
        """k candidate patches: gray weights, scene, stride, start (drawn in this order)."""
        if self.random_gray:
            w = 0.05 + rng.random((k, 3))
            w = w / w.sum(axis=1, keepdims=True)
        else:
            w = np.tile(np.asarray(GRAY_WEIGHTS, dtype=np.float64), (k, 1))
        scene = rng.choice(len(self.scenes), size=k, p=self.scene_p)
        stride = self.strides[rng.choice(len(self.strides), size=k, p=self.stride_p)]
        u = rng.random((k, 2))
        span = self.sizes[scene] - stride[:, None] * (self.patch - 1)  # positions where it fits, (k, 2)
        start = np.floor(u * np.maximum(span, 1)).astype(np.int64)
        return {"w": w.astype(np.float32), "scene": scene, "stride": stride, "y": start[:, 0], "x": start[:, 1],
                "fits": (span >= 1).all(axis=1)}

    def _indices(self, c: dict[str, np.ndarray], sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ar = np.arange(self.patch)
        ys = c["y"][sel, None] + c["stride"][sel, None] * ar  # (m, P)
        xs = c["x"][sel, None] + c["stride"][sel, None] * ar
        return ys[:, :, None], xs[:, None, :]

    def _accept(self, c: dict[str, np.ndarray]) -> np.ndarray:
        """Bool (M,): the candidate fits, avoids blocked pixels and has enough texture."""
        ok = c["fits"].copy()
        p = self.patch
        for j, scene in enumerate(self.scenes):  # one vectorised gather per scene
            sel = np.flatnonzero(ok & (c["scene"] == j))
            if sel.size == 0:
                continue
            ys, xs = self._indices(c, sel)
            if scene.blocked is not None:
                ok[sel] &= ~scene.blocked[ys, xs].any(axis=(1, 2))
            centre = scene.rgb[ys, xs, self.centre].astype(np.float32)  # (m, P, P, 3)
            gray = np.einsum("mpqc,mc->mpq", centre, c["w"][sel]) / np.float32(255.0)
            texture = np.abs(gray - gray[:, p // 2, p // 2][:, None, None]).sum(axis=(1, 2))
            ok[sel] &= texture >= self.texture * p * p
        return ok

    def _gather(self, c: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Gray patches (n, V, U, P, P) and labels (n, P, P) of the chosen candidates."""
        n, p = c["scene"].size, self.patch
        v, u = self.angular
        views = np.empty((n, v * u, p, p), dtype=np.float32)
        label = np.empty((n, p, p), dtype=np.float32)
        for j, scene in enumerate(self.scenes):
            sel = np.flatnonzero(c["scene"] == j)
            if sel.size == 0:
                continue
            ys, xs = self._indices(c, sel)
            rgb = scene.rgb[ys, xs].astype(np.float32)  # (m, P, P, N, 3)
            gray = np.einsum("mpqkc,mc->mkpq", rgb, c["w"][sel]) / np.float32(255.0)
            views[sel] = np.clip(gray, 0.0, 1.0)
            label[sel] = scene.disparity[ys, xs] / c["stride"][sel, None, None].astype(np.float32)
        return views.reshape(n, v, u, p, p), label

    # -- batches ---------------------------------------------------------------------------------

    def sample(self, seed: int, stage: int, step: int, start: int, count: int) -> tuple[np.ndarray, np.ndarray]:
        rngs = [sample_rng(seed, stage, step, start + i) for i in range(count)]
        chosen: list[dict[str, np.ndarray] | None] = [None] * count
        pending = list(range(count))
        k = self.candidates
        for _ in range(MAX_ROUNDS):
            if not pending:
                break
            draws = [self._draw(rngs[i], k) for i in pending]
            cand = {key: np.concatenate([d[key] for d in draws]) for key in draws[0]}
            ok = self._accept(cand).reshape(len(pending), k)
            still = []
            for row, i in enumerate(pending):
                hits = np.flatnonzero(ok[row])
                if hits.size:
                    chosen[i] = {key: val[row * k + hits[0]: row * k + hits[0] + 1] for key, val in cand.items()}
                else:
                    still.append(i)
            pending = still
        if pending:
            raise DataError(f"no patch passed the texture/mask rejection in {MAX_ROUNDS * k} tries; "
                            f"the training scenes may be too flat (data.texture = {self.texture}) or fully masked")
        picked = {key: np.concatenate([c[key] for c in chosen]) for key in chosen[0]}  # type: ignore[index]
        views, label = self._gather(picked)
        v, u = self.angular
        augments = [draw_augment(rng, self.augment, (v, u, self.patch, self.patch)) for rng in rngs]
        views, label = apply_augment(views, label, augments)
        return np.ascontiguousarray(views.reshape(count, v * u, self.patch, self.patch)), np.ascontiguousarray(label)


@dataclass
class ValidationScene:
    """A validation scene prepared for whole-image inference (standard gray, optional centre crop)."""

    name: str
    views: np.ndarray  # (N, h, w) float32 in [0, 1]
    gt: np.ndarray  # (h, w) float32


def validation_size(size: tuple[int, int], max_size: int = 0) -> tuple[int, int]:
    """(H, W) of a validation scene of ``size`` (H, W) px, centre-cropped to ``max_size`` px (0 = whole)."""
    h, w = size
    return (min(h, max_size), min(w, max_size)) if max_size else (h, w)


def load_validation_scene(scene: Scene, max_size: int = 0) -> ValidationScene:
    """Gray views and ground truth of ``scene``, centre-cropped to ``max_size`` px if larger (0 = whole)."""
    gt = scene.gt_disparity()
    if gt is None:
        raise DataError("validation scene has no ground truth disparity", scene.path)
    views = scene.gray_views()
    v, u, h, w = views.shape
    ch, cw = validation_size((h, w), max_size)
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    crop = np.array(views[:, :, y0:y0 + ch, x0:x0 + cw].reshape(v * u, ch, cw))  # a copy: the scene's views go
    scene.release_views()
    return ValidationScene(name=scene.name, views=crop, gt=np.asarray(gt[y0:y0 + ch, x0:x0 + cw], dtype=np.float32))
