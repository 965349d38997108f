"""A light field's camera: the geometry of a regular grid of views (focal length, sensor, baseline, focus
distance, resolution, number of views), the disparity <-> depth conversion it implies, and the scene's meta data
(disparity bounds, side ratio of the high-resolution ground truth, name, category).

A dataset adapter reads and writes it in its own format (HCI's: lfbench.data.hci.params); the
synthetic generator (lfbench.data.synth) makes one per scene, whatever layout the scene is written in.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["MAX_CAMS", "Camera"]

MAX_CAMS = 33  # views per side lfbench reads (HCI has 9x9)


@dataclass(frozen=True)
class Camera:
    """Camera and meta data of one scene (units in the names: mm, m, px); ``extra``: any other values, by
    section and key."""

    focal_length_mm: float
    image_resolution_x_px: int
    image_resolution_y_px: int
    sensor_size_mm: float
    num_cams_x: int
    num_cams_y: int
    baseline_mm: float
    focus_distance_m: float
    disp_min: float | None = None
    disp_max: float | None = None
    depth_map_scale: float = 10.0
    name: str | None = None
    category: str | None = None
    extra: dict[str, dict[str, str]] = field(default_factory=dict, compare=False, repr=False)

    @property
    def highres_scale(self) -> int:
        """Side ratio of the high-resolution ground truth to the views (depth_map_scale, 10 in HCI)."""
        return int(round(self.depth_map_scale))

    @property
    def angular_size(self) -> tuple[int, int]:
        """(rows V, columns U) of the camera grid."""
        return self.num_cams_y, self.num_cams_x

    @property
    def spatial_size(self) -> tuple[int, int]:
        """(H, W) in px."""
        return self.image_resolution_y_px, self.image_resolution_x_px

    def _disparity_factor_m(self) -> float:
        """b * f * N / s with b in m, so that d = factor * (1/Z - 1/F) for Z, F in m."""
        n = max(self.image_resolution_x_px, self.image_resolution_y_px)
        return (self.baseline_mm / 1000.0) * self.focal_length_mm * n / self.sensor_size_mm

    def depth_to_disparity(self, depth_m: np.ndarray) -> np.ndarray:
        """Depth in m (along the optical axis) -> disparity in px per view step."""
        q = self._disparity_factor_m()
        return q * (1.0 / np.asarray(depth_m, dtype=np.float64) - 1.0 / self.focus_distance_m)

    def disparity_to_depth(self, disparity: np.ndarray) -> np.ndarray:
        """Disparity in px per view step -> depth in m."""
        q = self._disparity_factor_m()
        return 1.0 / (np.asarray(disparity, dtype=np.float64) / q + 1.0 / self.focus_distance_m)
