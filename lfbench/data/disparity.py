"""The one check of a prediction: what a disparity map a method returns must be before it is written,
scored or validated (``lfbench predict``, ``evaluate``, ``bench``, the validation during training).

A prediction is a 2-D map of real floating-point values (px per view step; float16/32/64: not complex,
integer, boolean or object), of the light field's size (H, W) or a symmetric crop of it by at most
``max_crop`` px per side (the submissions' 482x482 of 512x512; scoring places it at the centre).
Non-finite values are allowed here: scoring counts them (``nonfinite_pixels`` of each scene) and
``lfbench predict`` reports how many a map holds. :func:`disparity_problem` is the rule, on a dtype and
a shape only, so that numpy maps (:func:`check_disparity`) and a network's tensors
(lfbench.method.trainable.contract_problem) are held to the same one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from lfbench.utils.errors import DataError

__all__ = ["EVALUATION_BORDER_PX", "check_disparity", "disparity_problem"]

#: The evaluation border, px left out at every side at low resolution: the one place it is written. The border of
#: every protocol that does not declare its own (HCI's, UrbanLF-Syn's, a dataset TOML's default), of training
#: validation and of figures drawn without a protocol; and the widest crop of a prediction (HCI's submissions are
#: 482x482 of 512x512).
EVALUATION_BORDER_PX = 15


def disparity_problem(real_floating: bool, dtype: str, shape: tuple[int, ...], expected: tuple[int, int], *,
                      max_crop: int | None = 0) -> str | None:
    """What is wrong with a map of dtype ``dtype`` (``real_floating``: whether it is a real floating type)
    and ``shape`` as a prediction for a light field of ``expected`` (H, W) px; None when nothing is.
    ``max_crop``: the widest symmetric crop accepted, px per side (0: exactly ``expected``; None: any)."""
    if not real_floating:
        return f"disparity must be real floating-point values, got {dtype}"
    if len(shape) != 2:
        return f"disparity must be a 2-D map, got shape {tuple(shape)}"
    h, w = expected
    if tuple(shape) == (h, w):
        return None
    dh, dw = h - shape[0], w - shape[1]
    if max_crop != 0 and dh >= 0 and dw >= 0 and not dh % 2 and not dw % 2 and \
            (max_crop is None or max(dh, dw) // 2 <= max_crop):
        return None
    allowed = "" if max_crop == 0 else " (only a symmetric crop of at most the evaluation border can be aligned)"
    return f"prediction is {shape[1]}x{shape[0]}, scene is {w}x{h}{allowed}"


def check_disparity(disparity: Any, expected: tuple[int, int], source: str, *, max_crop: int | None = 0
                    ) -> np.ndarray:
    """``disparity`` as a float32 (H, W) array after :func:`disparity_problem`; DataError naming ``source``
    (e.g. ``"tinycnn:weights=... on backgammon"``) when it is not an array of real numbers of the right size."""
    try:
        arr = np.asarray(disparity)
    except Exception:  # noqa: BLE001 - whatever a plugin returned (a CUDA tensor, a ragged list): one line
        arr = None
    if arr is None or arr.dtype == object:
        return _refuse(f"disparity must be an array of real floating-point values, got a {type(disparity).__name__}",
                       source)
    problem = disparity_problem(arr.dtype.kind == "f", str(arr.dtype), arr.shape, expected, max_crop=max_crop)
    if problem:
        _refuse(problem, source)
    return arr.astype(np.float32, copy=False)


def _refuse(problem: str, source: str) -> np.ndarray:
    raise DataError(f"{source}: {problem}")
