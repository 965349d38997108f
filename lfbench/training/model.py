"""The network a training run trains: its [model] values checked by the registered trainable, built, its
initial weights (``init``), its stored config, and each stage's optimizer from the trainable's
``configure_optimizers``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from lfbench.method.trainable import construct, get_trainable
from lfbench.training import checkpoint as ckpt
from lfbench.training.config import TrainConfig, expand_path
from lfbench.utils.errors import DataError, LFBenchError, SpecError


def check_model(cfg: TrainConfig) -> None:
    """The [model] values checked by the network (Trainable.check_params: its own checks, its size on the
    meta device) before anything is built, generated or written; SpecError naming the config."""
    try:
        get_trainable(cfg.method).check_params(cfg.model)
    except (TypeError, ValueError) as exc:
        raise SpecError(f"[model]: {exc}", cfg.source) from None


def model_angular(cfg: TrainConfig) -> int:
    """Views per angular row the config's network takes (its ``angular``; 9 where it declares none), read from
    a build on PyTorch's meta device (shapes only: nothing allocated or initialised)."""
    check_model(cfg)
    with torch.device("meta"):
        net = construct(get_trainable(cfg.method).build, cfg.model)
    return int(getattr(net, "angular", 9))


def load_init_weights(cfg: TrainConfig) -> tuple[Path, dict[str, torch.Tensor]]:
    """(path, state_dict) of ``cfg.init``: exported weights (``{"state_dict", "config", ...}``, loaded with
    weights_only=True); DataError naming the file when it is missing, unreadable or not in that format."""
    path = expand_path(cfg.init, cfg.source) if cfg.init else None
    if path is None:
        raise SpecError("init: no weights file given", cfg.source)
    payload = ckpt.load(path)
    state = payload.get("state_dict")
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise DataError("init weights: not an exported weights file (no state_dict of tensors; use a final.pt, "
                        "best.pt or stage*.pt of lfbench train)", path)
    return path, state


def build_model(cfg: TrainConfig) -> torch.nn.Module:
    """The config's trainable network built from [model]; SpecError naming the config for bad parameters."""
    check_model(cfg)
    trainable = get_trainable(cfg.method)
    try:
        model = construct(trainable.build, cfg.model)
    except (TypeError, ValueError) as exc:
        raise SpecError(f"[model]: {exc}", cfg.source) from None
    margin = trainable.output_margin(model)
    if cfg.data.patch <= 2 * margin:
        raise SpecError(f"[data] patch: {cfg.data.patch} px leaves nothing to train on: {cfg.method}'s output loses "
                        f"{margin} px per side (the loss compares the inner part); use patch >= {2 * margin + 1}",
                        cfg.source)
    return model


def network_config(cfg: TrainConfig, model: torch.nn.Module) -> dict[str, Any]:
    """What the weights files store as the network's config (``model.config()``, else the [model] table)."""
    return get_trainable(cfg.method).config_of(model, cfg.model)


def stage_optimizer(cfg: TrainConfig, model: torch.nn.Module, si: int
                    ) -> tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.LRScheduler | None]:
    """A fresh optimizer (and learning-rate schedule, or None) for stage ``si``, from the trainable
    network's :meth:`~lfbench.method.trainable.Trainable.configure_optimizers` (default: Adam with the stage's
    lr, betas and eps, constant rate)."""
    made = get_trainable(cfg.method).configure_optimizers(model, cfg.stages[si])
    optimizer, schedule = made if isinstance(made, tuple) else (made, None)
    if not isinstance(optimizer, torch.optim.Optimizer):
        raise LFBenchError(f"{cfg.method}: configure_optimizers returned a {type(optimizer).__name__}, not a "
                           "torch.optim.Optimizer")
    return optimizer, schedule


def describe_optimizer(optimizer: torch.optim.Optimizer) -> str:
    """E.g. 'Adam lr 0.001 eps 1e-07' (the first parameter group's rate, and epsilon when it has one)."""
    group = optimizer.param_groups[0]
    eps = f" eps {group['eps']:g}" if isinstance(group.get("eps"), float) else ""
    return f"{type(optimizer).__name__} lr {group['lr']:g}{eps}"


__all__ = ["build_model", "check_model", "model_angular", "describe_optimizer", "load_init_weights", "network_config",
           "stage_optimizer"]
