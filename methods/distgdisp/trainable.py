"""DistgDisp as a trainable network (the lfbench.method.trainable seam): what ``lfbench train`` builds from
``[model]``, what ``lfbench ablate`` varies, what ``lfbench bench`` times and what ``distgdisp:weights=FILE``
runs. Besides lfbench's own weights files, it loads the authors' released checkpoints as released: a
``.pth.tar`` holding ``{'state_dict': ...}`` with their key names (read with ``weights_only=True``), whose
architecture is read from the tensors' shapes (angular size, feature and cost channels) and whose disparity
grid is their code's, [-4, 4].

Light at import (no torch): the network module is imported when a network is built."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np

from lfbench.method.checkpoint import CHECKPOINT_FORMAT, read_checkpoint, read_weights
from lfbench.method.params import Range
from lfbench.method.trainable import Trainable, network_from_state, register_trainable
from lfbench.utils.errors import DataError

if TYPE_CHECKING:
    import torch

    from lfbench.data.scene import LightField

NETWORK = "lfbench_methods.distgdisp.network:DistgDispNet"
FEATURES = 16  # the authors' feaC
CHANNELS = 160  # the authors' channel (cost volume and 3D aggregation)
MAX_ANGULAR = 15
MAX_ABS_DISPARITY = 32  # px per view step
#: The tensor whose shape says the architecture of an authors' state_dict: (channels, features, A, A).
DSAFE_KEY = "build_costvolume.DSAFE.weight"
#: The disparity grid of the authors' released code (mindisp, maxdisp = -4, 4); their files do not store it.
AUTHORS_RANGE = (-4.0, 4.0)


def authors_config(state: dict, path: str | Path) -> dict[str, Any]:
    """The build parameters of an authors' DistgDisp state_dict, from its DSAFE kernel's shape; DataError
    naming ``path`` when the state_dict is not DistgDisp's (what it holds instead, in one line)."""
    import torch

    weight = state.get(DSAFE_KEY)
    if not isinstance(weight, torch.Tensor):
        keys = [str(k) for k in list(state)[:1]]
        holds = f"its first key is {keys[0][:60]!r}" if keys else "it is empty"
        raise DataError(f"a state_dict without {DSAFE_KEY!r}, not DistgDisp's ({holds})", path)
    if weight.dim() != 4 or weight.shape[2] != weight.shape[3]:
        raise DataError(f"{DSAFE_KEY!r} has shape {tuple(weight.shape)}, not DistgDisp's (channels, features, A, A)",
                        path)
    c, f, a, _ = (int(s) for s in weight.shape)
    return {"angular": a, "d_min": AUTHORS_RANGE[0], "d_max": AUTHORS_RANGE[1], "features": f, "channels": c}


def _without_prefix(state: dict) -> dict:
    """A state_dict saved from ``nn.DataParallel`` (every key ``module.``-prefixed) as the bare network's."""
    if state and all(isinstance(k, str) and k.startswith("module.") for k in state):
        return {k[len("module."):]: v for k, v in state.items()}
    return state


@register_trainable("distgdisp")
class DistgDispTrainable(Trainable):
    """DistgDisp (Wang et al., TPAMI 2022): forward -> (disparity, softmax probability over the integer disparity grid).

    Spatial features of every view (the authors' dilated convolutions on the macro-pixel image), the
    disparity-selective angular feature extractor (DSAFE) as a cost volume at every integer disparity
    from floor(d_min) to ceil(d_max), 3D aggregation and a soft argmin. Gray input as the authors' (the
    mean of R, G and B). Loads the authors' released .pth.tar as it is (their grid, [-4, 4]). Exact tiled
    inference (tile=...) with a receptive radius of 20 + (A - 1) / 2 * max|d| + 8 px.
    """

    network = NETWORK
    distribution = True
    axes = ("angular", "d_min", "d_max", "features", "channels")

    def build(
        self,
        angular: Annotated[int, "views per angular row (A x A views; the dilation of the authors' MacPI convolutions "
                                "is A; odd, e.g. 9, 7, 5)", Range(3, MAX_ANGULAR)] = 9,
        d_min: Annotated[float, "smallest disparity searched (px); the grid is the integers floor(d_min) .. "
                                "ceil(d_max), the authors' [-4, 4]", Range(-MAX_ABS_DISPARITY, MAX_ABS_DISPARITY)]
        = -4.0,
        d_max: Annotated[float, "largest disparity searched (px; see d_min)",
                         Range(-MAX_ABS_DISPARITY, MAX_ABS_DISPARITY)] = 4.0,
        features: Annotated[int, "channels of the spatial features (the authors' 16)", Range(1, 1024)] = FEATURES,
        channels: Annotated[int, "channels of the cost volume and the 3D aggregation (the authors' 160)",
                            Range(1, 1024)] = CHANNELS,
    ) -> Any:
        """The DistgDispNet of these parameters (declared here, so that listing them imports no torch)."""
        from lfbench_methods.distgdisp.network import DistgDispNet

        return DistgDispNet(angular=angular, d_min=d_min, d_max=d_max, features=features, channels=channels)

    def check(self, params: dict[str, Any]) -> None:
        """The network's own checks (network.check_config), without building it."""
        from lfbench_methods.distgdisp.network import check_config

        check_config(**{**{k: p.default for k, p in self.parameters().items()}, **params})

    def cost_estimate(self, model: dict[str, Any], steps: int) -> float:
        """Disparities x channels^2 x steps (the 3D aggregation dominates)."""
        from lfbench_methods.distgdisp.network import disparity_range

        p = {**{k: v.default for k, v in self.parameters().items()}, **model}
        lo, hi = disparity_range(p["d_min"], p["d_max"])
        return float((hi - lo + 1) * int(p["channels"]) ** 2 * steps)

    def flops(self, net: torch.nn.Module, height: int, width: int) -> dict[str, float]:
        return net.flops(height, width)

    def views_of(self, lf: LightField) -> np.ndarray:
        """The authors' gray: the mean of R, G and B (their test code's ``np.mean(lf / 255, axis=-1)``); a light
        field that only has gray views gives those."""
        rgb = getattr(lf, "rgb_views", None)
        if rgb is None:
            return lf.gray_views()
        return np.mean(rgb(), axis=-1, dtype=np.float32)

    # -- weights: lfbench's files and the authors' .pth.tar ------------------------------------------

    def _payload(self, path: str | Path) -> dict[str, Any]:
        payload = read_checkpoint(path, "weights file")
        state = payload.get("state_dict")
        if isinstance(state, dict) and "config" not in payload and payload.get("format") != CHECKPOINT_FORMAT:
            state = _without_prefix(state)
            return {"state_dict": state, "config": authors_config(state, path), "method": self.name}
        return read_weights(path, self.name or None, self.same_network())

    def stored_config(self, path: str | Path) -> dict[str, Any]:
        return dict(self._payload(path)["config"])

    def load(self, path: str | Path, **overrides: Any) -> torch.nn.Module:
        """The network of an lfbench weights file or of an authors' ``{'state_dict': ...}`` checkpoint (eval
        mode); DataError naming the file otherwise (another network's, another size, damaged)."""
        payload = self._payload(path)
        return network_from_state(self.build, payload["state_dict"], {**payload["config"], **overrides}, path)

    def receptive_radius(self, net: torch.nn.Module) -> int | None:
        return int(net.receptive_radius)


__all__ = ["DistgDispTrainable", "NETWORK", "authors_config", "AUTHORS_RANGE", "DSAFE_KEY"]
