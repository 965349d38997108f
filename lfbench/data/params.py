"""parameters.cfg of an HCI scene: camera geometry and the depth <-> disparity conversion."""

from __future__ import annotations

import configparser
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lfbench.utils.errors import DataError

# (section, key, type) of every value lfbench needs; the rest of the file is kept in ``extra``.
REQUIRED_KEYS: tuple[tuple[str, str, type], ...] = (
    ("intrinsics", "focal_length_mm", float),
    ("intrinsics", "image_resolution_x_px", int),
    ("intrinsics", "image_resolution_y_px", int),
    ("intrinsics", "sensor_size_mm", float),
    ("extrinsics", "num_cams_x", int),
    ("extrinsics", "num_cams_y", int),
    ("extrinsics", "baseline_mm", float),
    ("extrinsics", "focus_distance_m", float),
)


@dataclass(frozen=True)
class SceneParameters:
    """Camera and meta data of one scene (units in the names: mm, m, px)."""

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

    def to_cfg(self) -> str:
        """The parameters as parameters.cfg text (HCI layout)."""
        sections: dict[str, dict[str, str]] = {k: dict(v) for k, v in self.extra.items()}
        for section, key, _ in REQUIRED_KEYS:
            sections.setdefault(section, {})[key] = repr(getattr(self, key))
        meta = sections.setdefault("meta", {})
        for key in ("disp_min", "disp_max", "depth_map_scale", "name", "category"):
            value = getattr(self, key)
            if value is not None:
                meta["scene" if key == "name" else key] = str(value)
        lines = []
        known = ("intrinsics", "extrinsics", "meta")
        for section in (*known, *sorted(set(sections) - set(known))):
            if section in sections:
                lines.append(f"[{section}]")
                lines += [f"{k} = {v}" for k, v in sections[section].items()]
                lines.append("")
        return "\n".join(lines)


def read_parameters(path: str | Path) -> SceneParameters:
    """Parse a parameters.cfg; DataError naming the file for a missing file, section or key."""
    path = Path(path)
    if not path.is_file():
        raise DataError("missing parameters.cfg", path)
    parser = configparser.ConfigParser(interpolation=None)
    try:
        parser.read_string(path.read_text(encoding="utf-8", errors="replace"), source=str(path))
    except configparser.Error as exc:
        raise DataError(f"cannot parse: {str(exc).splitlines()[0]}", path) from None
    values: dict[str, object] = {}
    for section, key, kind in REQUIRED_KEYS:
        if not parser.has_option(section, key):
            raise DataError(f"missing required key [{section}] {key}", path)
        raw = parser.get(section, key)
        try:
            values[key] = kind(float(raw)) if kind is int else kind(raw)
        except ValueError:
            raise DataError(f"[{section}] {key} = {raw!r} is not a number", path) from None
    if values["num_cams_x"] < 1 or values["num_cams_y"] < 1:  # type: ignore[operator]
        raise DataError("num_cams_x and num_cams_y must be positive", path)

    def meta(key: str, default=None):
        if not parser.has_option("meta", key):
            return default
        try:
            return float(parser.get("meta", key))
        except ValueError:
            raise DataError(f"[meta] {key} is not a number", path) from None

    extra = {s: dict(parser.items(s)) for s in parser.sections()}
    return SceneParameters(
        **values,  # type: ignore[arg-type]
        disp_min=meta("disp_min"),
        disp_max=meta("disp_max"),
        depth_map_scale=meta("depth_map_scale", 10.0),
        name=parser.get("meta", "scene", fallback=None),
        category=parser.get("meta", "category", fallback=None),
        extra=extra,
    )
