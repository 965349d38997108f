"""parameters.cfg of an HCI scene: its camera (lfbench.data.camera.Camera: geometry and the depth <-> disparity
conversion) read and written in HCI's format."""

from __future__ import annotations

import configparser
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from lfbench.data.camera import MAX_CAMS, Camera
from lfbench.data.scene import MAX_RESOLUTION_PX, MAX_VIEW_PIXELS
from lfbench.utils.errors import DataError
from lfbench.utils.readfile import read_text

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


# Bounds checked before anything is allocated from these numbers (a 1 kB file must not ask for 100 GB).
MAX_DEPTH_MAP_SCALE = 16  # side ratio of the high-resolution ground truth (HCI: 10)
MAX_PARAMETERS_BYTES = 1024**2  # the file itself (HCI's: under 1 kB)
_POSITIVE = {"focal_length_mm", "sensor_size_mm", "focus_distance_m"}


def _checked(section: str, key: str, number: float, kind: type, path: Path) -> int | float:
    """One required value, range-checked: counts are whole numbers within their bound, lengths finite
    (and > 0 where 0 would divide)."""
    where = f"[{section}] {key} = {number:g}"
    if not np.isfinite(number):
        raise DataError(f"{where} must be a finite number", path)
    if kind is float:
        if key in _POSITIVE and number <= 0:
            raise DataError(f"{where} must be > 0", path)
        return number
    limit = MAX_CAMS if key.startswith("num_cams") else MAX_RESOLUTION_PX
    if number != round(number) or not 1 <= number <= limit:
        raise DataError(f"{where} must be a whole number from 1 to {limit}", path)
    return int(number)


@dataclass(frozen=True)
class SceneParameters(Camera):
    """A scene's camera and meta data (lfbench.data.camera.Camera) as parameters.cfg holds them."""

    @classmethod
    def of(cls, camera: Camera) -> SceneParameters:
        """``camera`` as parameters.cfg's (the same values)."""
        if isinstance(camera, cls):
            return camera
        return cls(**{f.name: getattr(camera, f.name) for f in fields(Camera)})

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
    text = read_text(path, "parameters.cfg", MAX_PARAMETERS_BYTES, errors="replace")
    try:
        parser.read_string(text, source=str(path))
    except configparser.Error as exc:
        raise DataError(f"cannot parse: {str(exc).splitlines()[0]}", path) from None
    values: dict[str, object] = {}
    for section, key, kind in REQUIRED_KEYS:
        if not parser.has_option(section, key):
            raise DataError(f"missing required key [{section}] {key}", path)
        raw = parser.get(section, key)
        try:
            number = float(raw)
        except ValueError:
            raise DataError(f"[{section}] {key} = {raw[:40]!r} is not a number", path) from None
        values[key] = _checked(section, key, number, kind, path)
    views = values["num_cams_x"] * values["num_cams_y"] * values["image_resolution_x_px"] \
        * values["image_resolution_y_px"]  # type: ignore[operator]
    if views > MAX_VIEW_PIXELS:
        raise DataError(f"{values['num_cams_x']}x{values['num_cams_y']} views of {values['image_resolution_x_px']}x"
                        f"{values['image_resolution_y_px']} px is {views:.3g} pixels, more than lfbench reads "
                        f"({MAX_VIEW_PIXELS:.3g})", path)

    def meta(key: str, default=None):
        if not parser.has_option("meta", key):
            return default
        try:
            value = float(parser.get("meta", key))
        except ValueError:
            raise DataError(f"[meta] {key} is not a number", path) from None
        if not np.isfinite(value):
            raise DataError(f"[meta] {key} = {value} must be a finite number", path)
        return value

    scale = meta("depth_map_scale", 10.0)
    if scale != round(scale) or not 1 <= scale <= MAX_DEPTH_MAP_SCALE:
        raise DataError(f"[meta] depth_map_scale = {scale:g} must be a whole number from 1 to {MAX_DEPTH_MAP_SCALE}",
                        path)
    extra = {s: dict(parser.items(s)) for s in parser.sections()}
    return SceneParameters(
        **values,  # type: ignore[arg-type]
        disp_min=meta("disp_min"),
        disp_max=meta("disp_max"),
        depth_map_scale=scale,
        name=parser.get("meta", "scene", fallback=None),
        category=parser.get("meta", "category", fallback=None),
        extra=extra,
    )
