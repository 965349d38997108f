"""What a method is: something that turns a light field into a disparity map."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from lfbench.data.scene import LightField


@dataclass
class Prediction:
    """A method's output for one light field.

    disparity: (H, W) float32, px per view step. distribution: (D, H, W) float32 probabilities over
    ``disparity_values`` (D,) when the method has one; uncertainty: (H, W) float32 (larger = less
    sure). runtime_s: wall time of the prediction in s (a precomputed result carries its own).
    """

    disparity: np.ndarray
    distribution: np.ndarray | None = None
    disparity_values: np.ndarray | None = None
    uncertainty: np.ndarray | None = None
    runtime_s: float | None = None


class Method:
    """Base class of registered methods. Subclasses implement :meth:`predict`.

    The registry sets ``name`` and ``params`` (the parameters it was created with).
    """

    name: str = ""
    params: dict

    def __init__(self, **params) -> None:
        self.params = dict(params)

    @property
    def label(self) -> str:
        """How results name this method: the canonical spec ``name:key=value,...``."""
        from lfbench.method.registry import format_spec

        return format_spec(self.name, self.params)

    def available_for(self, lf: LightField) -> str | None:
        """None if the method can run on ``lf``, else a one-line reason (e.g. no stored map)."""
        return None

    def predict(self, lf: LightField) -> Prediction:
        raise NotImplementedError

    def to(self, device: str) -> Method:
        """Run on ``device`` (``cpu``, ``cuda``, ``cuda:1``): a method with a network moves it there.
        The default (a method without one) runs where it is and returns itself."""
        return self

    def run(self, lf: LightField) -> Prediction:
        """predict() with the wall time recorded (unless the prediction carries its own runtime)."""
        start = time.perf_counter()
        pred = self.predict(lf)
        elapsed = time.perf_counter() - start
        if pred.runtime_s is None:
            pred.runtime_s = elapsed
        pred.disparity = np.asarray(pred.disparity, dtype=np.float32)
        return pred
