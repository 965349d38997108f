"""SubFocal and LFattNet as trainable networks (the lfbench.method.trainable seam): what ``lfbench train``
builds from ``[model]``, what ``lfbench ablate`` varies, what ``lfbench bench`` times (with SubFocal's own
benches, ``peak`` and ``volume``, and its own training-bench options, ``--path`` and ``--weight-grad``).

Light at import (no torch): the network module is imported when a network is built."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from lfbench_methods.subfocal.bench import bench_peak, bench_volume

from lfbench.method.trainable import Trainable, register_trainable
from lfbench.utils.options import option

if TYPE_CHECKING:
    import torch
    from lfbench_methods.subfocal.network import SubFocalNet

#: Where the network lives: imported only when one is built (``lfbench methods`` does not need torch).
NETWORK = "lfbench_methods.subfocal.network:SubFocalNet"
TRAINING_PATHS = ("fast", "reference")
WEIGHT_GRADS = ("auto", "gemm", "native")


@dataclass(frozen=True, kw_only=True)
class SubFocalTrainBench:
    """SubFocal's options of ``lfbench bench train`` (``--path``, ``--weight-grad``: one or more values each, a
    variant per combination)."""

    path: tuple[Literal[TRAINING_PATHS], ...] = option(  # type: ignore[valid-type]
        ("fast",), help="training path(s): fast (what lfbench train runs) and/or reference (the original ops: the "
        "'before' of the training speed-up)")
    weight_grad: tuple[Literal[WEIGHT_GRADS] | None, ...] = option(  # type: ignore[valid-type]
        (None,), help="fast path: convolution weight gradients as matrix products where they pay (auto, the "
        "default), on every layer they apply to (gemm), or PyTorch's own (native)")


@register_trainable("subfocal")
class SubFocalTrainable(Trainable):
    """SubFocal (Chao et al., TCI 2023): forward -> (disparity, softmax probability over the disparity grid)."""

    network = NETWORK  # its method is SubFocal's own (methods/subfocal/method.py: shipped weights, Keras import)
    distribution = True
    axes = ("interval", "interpolation", "width", "attention", "d_min", "d_max")
    benches = {"peak": bench_peak, "volume": bench_volume}
    train_bench_options = SubFocalTrainBench
    train_bench_defaults = {"width": (150, 16)}  # the paper's width and the small one lfbench trains on a CPU

    def check(self, params: dict[str, Any]) -> None:
        """The network's own parameter checks (network.check_config), without building the (paper-size) network."""
        from lfbench_methods.subfocal.network import check_config

        check_config(**{**{k: p.default for k, p in self.parameters().items()}, **params})

    def cost_estimate(self, model: dict[str, Any], steps: int) -> float:
        """Candidate disparities x steps (the cost volume dominates); the phase-shift interpolation about 1.6x."""
        params = {**{k: p.default for k, p in self.parameters().items()}, **model}
        d = (float(params["d_max"]) - float(params["d_min"])) / float(params["interval"]) + 1
        return d * steps * (1.6 if params.get("interpolation") == "phase" else 1.0)

    def load(self, path: str | Path, **overrides: Any) -> SubFocalNet:
        from lfbench_methods.subfocal.keras_import import build_from_checkpoint

        return build_from_checkpoint(path, network=self.name or None, **overrides)

    def can_tile(self, net: SubFocalNet) -> bool:
        return True  # infer tiles exactly (features and attention of the whole image, a 9 px halo per tile)

    def infer(self, net: SubFocalNet, views: torch.Tensor, *, precision: str = "fp32",
              max_memory_gb: float | None = 4.0, tile: int = 0,
              timings: dict | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Whole-image or exactly tiled inference on the network's device (tiles from ``max_memory_gb`` when
        tile = 0; None: the device's budget, see inference.memory_budget_gb); ``timings`` receives the phases,
        the tile size and the number of tiles."""
        from lfbench_methods.subfocal.inference import infer, memory_budget_gb, plan_tiles

        out = infer(net, views, tile=tile, max_memory_gb=max_memory_gb, precision=precision, timings=timings)
        if timings is not None and "tile" not in timings:
            h, w = views.shape[-2:]
            device = net.disparities.device
            timings["tile"] = plan_tiles(net, h, w, max_memory_gb=memory_budget_gb(device, max_memory_gb),
                                         precision=precision, device=device) if tile == 0 else (tile, tile)
        return out.disparity, out.probability

    def flops(self, net: SubFocalNet, height: int, width: int) -> dict[str, float]:
        return net.flops(height, width)

    def train_variants(self, chosen: dict[str, list[str | None]]) -> list[dict[str, str]]:
        """Every path; the weight-gradient choices apply to the fast path only."""
        grads = chosen.get("weight_grad") or [None]
        return [{"path": path, **({"weight_grad": grad} if grad is not None else {})}
                for path in chosen.get("path") or ["fast"] for grad in (grads if path == "fast" else [None])]

    def prepare_training(self, net: SubFocalNet, *, path: str = "fast", weight_grad: str | None = None) -> bool:
        """``path``: fast (what lfbench train runs) or reference (the original ops, the "before", with the
        default heap); ``weight_grad`` (fast path only): auto, gemm or native weight gradients."""
        if weight_grad is not None and path != "fast":
            raise ValueError("weight_grad applies to the fast training path only")
        net.set_training_path(path, **({} if weight_grad is None else {"weight_grad": weight_grad}))
        return path == "fast"


@register_trainable("lfattnet")
class LFAttNetTrainable(SubFocalTrainable):
    """LFattNet (Tsai et al., AAAI 2020), SubFocal's baseline: the same network at integer disparities."""

    defaults = {"interval": 1.0}


__all__ = ["SubFocalTrainable", "LFAttNetTrainable", "NETWORK"]
