"""``gt``: returns the scene's ground truth (a sanity check of the scoring pipeline)."""

from __future__ import annotations

from lfbench.data.scene import LightField
from lfbench.method.base import Method, Prediction
from lfbench.method.registry import register_method
from lfbench.utils.errors import DataError


@register_method("gt")
class GroundTruthOracle(Method):
    """Oracle: the scene's own low-resolution ground truth (every metric is perfect; a reference, not ranked)."""

    oracle = True

    def __init__(self) -> None:
        super().__init__()

    def available_for(self, lf: LightField) -> str | None:
        return None if lf.gt_disparity() is not None else "the scene has no ground truth"

    def predict(self, lf: LightField) -> Prediction:
        gt = lf.gt_disparity()
        if gt is None:
            raise DataError(f"gt: scene {lf.name!r} has no ground truth")
        return Prediction(disparity=gt.copy())
