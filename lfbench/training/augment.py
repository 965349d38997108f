"""The authors' per-sample augmentation, applied to a batch at once, geometry-consistent.

Patches are (n, V, U, P, P) float32 in [0, 1] with ``views[i, v, u]`` the view at angular row v,
column u, and labels (n, P, P) disparity in px per view step. The light-field geometry
``centre(x, y) = view_{u,v}(x - (u - uc) d, y - (v - vc) d)`` is kept with the same disparity
sign: flipping the image rows also flips the angular row index v, and a rotation by k * 90
degrees turns the angular (v, u) axes together with the spatial (y, x) axes.

Order (the authors' code; docs/subfocal-training.md, Augmentation): gamma x^g, g ~ U(0.8, 1.2);
row flip with p = 0.5; rotation by k * 90
degrees, k uniform in {0..3}; Gaussian noise with p = 1/12, std ~ U(0, 1) * sqrt(0.2); clip to [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfbench.training.config import AugmentConfig


def flip_rows(views: np.ndarray, label: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flip image rows y -> P-1-y and the angular row v -> V-1-v: (n, V, U, P, P), (n, P, P)."""
    return views[:, ::-1, :, ::-1, :], label[:, ::-1, :]


def rotate90(views: np.ndarray, label: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Rotate by k * 90 degrees: spatial (y, x) and angular (v, u) axes turned the same way."""
    views = np.rot90(np.rot90(views, k, axes=(3, 4)), k, axes=(1, 2))
    return views, np.rot90(label, k, axes=(1, 2))


@dataclass
class SampleAugment:
    """One sample's random augmentation: gamma, flip, rotation k, and a noise field or None."""

    gamma: float = 1.0
    flip: bool = False
    rotation: int = 0
    noise: np.ndarray | None = None  # (V, U, P, P) float32 additive noise


def draw_augment(rng: np.random.Generator, cfg: AugmentConfig, shape: tuple[int, ...]) -> SampleAugment:
    """Draw one sample's augmentation from ``rng`` in the authors' order; ``shape`` = (V, U, P, P)."""
    if not cfg.enabled:
        return SampleAugment()
    gamma = float(rng.uniform(cfg.gamma[0], cfg.gamma[1]))
    flip = bool(rng.random() < cfg.flip)
    rotation = int(rng.integers(4)) if cfg.rotate else 0
    noise = None
    if rng.random() < cfg.noise:
        std = float(rng.random()) * cfg.noise_std
        noise = rng.normal(0.0, std, size=shape).astype(np.float32)
    return SampleAugment(gamma=gamma, flip=flip, rotation=rotation, noise=noise)


def apply_augment(views: np.ndarray, label: np.ndarray,
                  augments: list[SampleAugment]) -> tuple[np.ndarray, np.ndarray]:
    """Apply per-sample augmentations to a batch (vectorised per kind of transform).

    views (n, V, U, P, P) float32 in [0, 1], label (n, P, P) -> new arrays of the same shapes.
    """
    n = views.shape[0]
    if len(augments) != n:
        raise ValueError(f"{len(augments)} augmentations for {n} samples")
    if views.shape[3] != views.shape[4] and any(a.rotation % 2 for a in augments):
        raise ValueError("90-degree rotations need square patches")
    gamma = np.array([a.gamma for a in augments], dtype=np.float32)
    views = np.power(views, gamma[:, None, None, None, None], dtype=np.float32)
    label = np.array(label, dtype=np.float32, copy=True)
    flip = np.array([a.flip for a in augments], dtype=bool)
    if flip.any():
        views[flip], label[flip] = flip_rows(views[flip], label[flip])
    rotation = np.array([a.rotation % 4 for a in augments])
    for k in (1, 2, 3):
        sel = rotation == k
        if sel.any():
            views[sel], label[sel] = rotate90(views[sel], label[sel], k)
    noisy = [i for i, a in enumerate(augments) if a.noise is not None]
    if noisy:
        views[noisy] += np.stack([augments[i].noise for i in noisy])
    np.clip(views, 0.0, 1.0, out=views)
    return views, label
