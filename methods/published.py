"""``published``: disparity maps precomputed by someone else, read from a submission folder."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from lfbench.data.scene import LightField
from lfbench.data.submission import check_inside, find_disp_map, read_submission_map
from lfbench.method.base import Method, Prediction
from lfbench.method.registry import register_method
from lfbench.utils.errors import DataError


def _scene_shape(lf: LightField) -> tuple[int, int] | None:
    """(H, W) of the scene's views when it knows them without reading images (a stored map is checked
    against it before its data is read), else None."""
    shape = getattr(lf, "spatial_size", None)
    return tuple(shape) if shape is not None else None


@register_method("published")
class PublishedResults(Method):
    """Precomputed results in the benchmark's submission layout (disp_maps/, runtimes/)."""

    def __init__(self, path: Annotated[Path, "the submission folder (holding disp_maps/<scene>.pfm or .npy "
                                             "and runtimes/<scene>.txt)"]) -> None:
        super().__init__(path=path)
        self.path = Path(path)
        if not (self.path / "disp_maps").is_dir():
            raise ValueError(f"{self.path}: not a submission folder (no disp_maps/ inside)")

    @property
    def label(self) -> str:
        """``published:<folder name>``, or the label given (``--label``, :meth:`with_label`)."""
        return super().label if self._given_label else f"published:{self.path.resolve().name}"

    def available_for(self, lf: LightField) -> str | None:
        p = find_disp_map(self.path, lf.name)
        if not (p.exists() or p.is_symlink()):
            return f"no {p}"
        check_inside(self.path, p)
        return None

    def predict(self, lf: LightField) -> Prediction:
        path = find_disp_map(self.path, lf.name)
        if not (path.exists() or path.is_symlink()):
            raise DataError(f"no disparity map for scene {lf.name!r}", path)
        disparity, runtime = read_submission_map(self.path, lf.name, max_shape=_scene_shape(lf))
        return Prediction(disparity=disparity, runtime_s=float("nan") if runtime is None else runtime)
