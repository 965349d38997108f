"""The registered method ``planesweep`` (the pipeline: methods/planesweep/estimator.py). Light at import:
torch is imported when the method is made."""

from __future__ import annotations

import functools
from typing import Annotated, Literal

import numpy as np

from lfbench.data.scene import LightField
from lfbench.method.base import Method, Prediction
from lfbench.method.params import Param, Range, signature_params, values_problem
from lfbench.method.registry import register_method
from lfbench.utils.errors import DataError
from lfbench.utils.hardware import DEVICE_HELP
from lfbench.utils.options import Bounds

MAX_RADIUS_PX = 256  # norm_radius and arm_length: windows wider than this only cost time and memory
POSITIVE = Bounds(0, None, low_open=True)  # arm_tau and temperature: finite numbers > 0


@register_method("planesweep")
class PlaneSweep(Method):
    """Training-free plane sweep with occlusion-aware view subsets, edge-aware aggregation and sub-pixel fit."""

    def __init__(
        self,
        d_min: Annotated[float, "smallest candidate disparity, px per view step (SubFocal: -4)"] = -4.0,
        d_max: Annotated[float, "largest candidate disparity, px per view step (SubFocal: 4)"] = 4.0,
        interval: Annotated[float, "spacing of the candidate disparities in px (SubFocal: 0.5; 0.25 is finer and "
                                   "more accurate)"] = 0.25,
        interpolation: Annotated[Literal["nearest", "bilinear", "phase"],
                                 "how views are shifted onto the centre: nearest, bilinear or phase (Fourier "
                                 "shift)"] = "bilinear",
        views: Annotated[Literal["star", "all"], "star (centre row, column and both diagonals: 33 of 81 views, "
                                                 "about as accurate) or all"] = "star",
        occlusion: Annotated[Literal["subsets", "none"], "subsets (best of all/half-aperture/centre-row/centre-"
                                                         "column view subsets per pixel) or none"] = "subsets",
        norm_radius: Annotated[int, "radius in px of the local contrast normalisation of the views (0: raw gray "
                                    "levels)", Range(0, MAX_RADIUS_PX)] = 2,
        arm_length: Annotated[int, "longest arm in px of the cross-shaped aggregation windows (0: no aggregation)",
                              Range(0, MAX_RADIUS_PX)] = 16,
        arm_tau: Annotated[float, "gray-level tolerance (0..1) under which the aggregation arms keep growing",
                           POSITIVE] = 0.02,
        subpixel: Annotated[Literal["equiangular", "parabola", "none"],
                            "fit through the cost minimum: equiangular (suits the L1 cost), parabola or none"]
        = "equiangular",
        temperature: Annotated[float, "softmax temperature of the returned distribution, in units of each pixel's "
                                      "mean cost", POSITIVE] = 0.05,
        device: Annotated[str, f"where the sweep runs: {DEVICE_HELP}"] = "auto",
    ) -> None:
        from lfbench_methods.planesweep.estimator import OCCLUSION_MODES, SUBPIXEL_FITS, VIEW_SETS

        from lfbench.data.shift import INTERPOLATIONS, disparity_grid
        from lfbench.utils.hardware import resolve_device

        super().__init__(d_min=d_min, d_max=d_max, interval=interval, interpolation=interpolation, views=views,
                         occlusion=occlusion, norm_radius=norm_radius, arm_length=arm_length, arm_tau=arm_tau,
                         subpixel=subpixel, temperature=temperature, device=device)
        self.disparities = disparity_grid(d_min, d_max, interval)  # ValueError on a bad grid
        for name, value, allowed in (("interpolation", interpolation, INTERPOLATIONS), ("views", views, VIEW_SETS),
                                     ("occlusion", occlusion, OCCLUSION_MODES), ("subpixel", subpixel, SUBPIXEL_FITS)):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")
        problem = values_problem(_declared(), {"norm_radius": norm_radius, "arm_length": arm_length,
                                               "arm_tau": arm_tau, "temperature": temperature})
        if problem:
            raise ValueError(f"{problem[0]}: {problem[1]}")  # the declared Range / Bounds, as a spec value is checked
        self.interval = float(interval)
        self.interpolation = interpolation
        self.views = views
        self.device = resolve_device(device)  # SpecError before any work for a device this machine lacks
        self.occlusion = occlusion
        self.norm_radius = int(norm_radius)
        self.arm_length = int(arm_length)
        self.arm_tau = float(arm_tau)
        self.subpixel = subpixel
        self.temperature = float(temperature)

    def predict(self, lf: LightField) -> Prediction:
        import torch
        from lfbench_methods.planesweep.estimator import estimate

        from lfbench.data.shift import angular_offsets

        rows, cols = lf.angular_size
        if rows * cols < 2:
            raise DataError(f"planesweep: {lf.name!r} has a single view; a plane sweep needs parallax")
        gray = np.asarray(lf.gray_views(), dtype=np.float32)
        if gray.ndim != 4 or gray.shape[:2] != (rows, cols):
            raise DataError(f"planesweep: {lf.name!r} views have shape {gray.shape}, expected ({rows}, {cols}, H, W)")
        if not np.isfinite(gray).all():
            raise DataError(f"planesweep: {lf.name!r} views contain NaN or infinite values")
        with torch.inference_mode():
            views = torch.from_numpy(gray).reshape(rows * cols, *gray.shape[2:]).to(self.device)
            _, disp, dist, unc = estimate(views, angular_offsets(rows, cols), self.disparities, self.interval,
                                          interpolation=self.interpolation, view_set=self.views,
                                          occlusion=self.occlusion, norm_radius=self.norm_radius,
                                          arm_length=self.arm_length, arm_tau=self.arm_tau,
                                          subpixel=self.subpixel, temperature=self.temperature)
        return Prediction(disparity=disp.cpu().numpy().astype(np.float32), distribution=dist.cpu().numpy(),
                          disparity_values=self.disparities.numpy(), uncertainty=unc.cpu().numpy())


__all__ = ["PlaneSweep", "MAX_RADIUS_PX"]


@functools.cache
def _declared() -> dict[str, Param]:
    """The declared parameters of :class:`PlaneSweep` (types, defaults, bounds)."""
    return signature_params(PlaneSweep)
