"""``constant``: the same disparity at every pixel; ``constant`` (0 px) is the zero map a learned result is
reported beside (with the plane sweep): a network that does not beat it has learned nothing about depth."""

from __future__ import annotations

import math

import numpy as np

from lfbench.data.scene import LightField
from lfbench.data.shift import MAX_ABS_DISPARITY
from lfbench.method.base import Method, Prediction
from lfbench.method.registry import register_method


@register_method("constant")
class ConstantDisparity(Method):
    """Baseline: one disparity everywhere (default 0 px, the zero map).

    value: the disparity in px per view step, |value| <= 64
    """

    def __init__(self, value: float = 0.0) -> None:
        super().__init__(value=value)
        if not (math.isfinite(value) and abs(value) <= MAX_ABS_DISPARITY):
            raise ValueError(f"value must be a finite disparity of at most {MAX_ABS_DISPARITY:g} px, got {value}")
        self.value = float(value)

    def predict(self, lf: LightField) -> Prediction:
        height, width = lf.center_view().shape[:2]
        return Prediction(disparity=np.full((height, width), self.value, dtype=np.float32))
