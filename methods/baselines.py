"""``constant``: the same disparity at every pixel; ``constant`` (0 px) is the zero map a learned result is
reported beside (with the plane sweep): a network that does not beat it has learned nothing about depth."""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np

from lfbench.data.scene import LightField
from lfbench.method.base import Method, Prediction
from lfbench.method.registry import register_method


@register_method("constant")
class ConstantDisparity(Method):
    """Baseline: one disparity everywhere (default 0 px, the zero map)."""

    def __init__(self, value: Annotated[float, "the disparity in px per view step, |value| <= 64"] = 0.0) -> None:
        from lfbench.data.shift import MAX_ABS_DISPARITY  # (torch comes with it: only when a method is made)

        super().__init__(value=value)
        if not (math.isfinite(value) and abs(value) <= MAX_ABS_DISPARITY):
            raise ValueError(f"value must be a finite disparity of at most {MAX_ABS_DISPARITY:g} px, got {value}")
        self.value = float(value)

    def predict(self, lf: LightField) -> Prediction:
        height, width = lf.center_view().shape[:2]
        return Prediction(disparity=np.full((height, width), self.value, dtype=np.float32))
