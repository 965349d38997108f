"""What each cell of an ablation is, read from its training config: its variant and seed, its [model]
values (the network's default where the config gives none), its last stage's loss and that loss's
``beta``. Shared by the report, the significance tests and the baseline verdicts (all above this
module: it imports none of them)."""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
import pandas as pd

from lfbench.ablation.spec import AblationSpec, cell_id, network_default, variant_values
from lfbench.method.trainable import DEFAULT_TRAINABLE
from lfbench.training.config import STAGE_KEYS
from lfbench.training.losses import LOSSES

__all__ = ["cell_info", "last_stage_loss", "loss_beta", "model_value", "network_of"]


def network_of(spec: AblationSpec) -> str:
    """The registered trainable network the spec's cells train (the default network without cells)."""
    return spec.cells[0].config.get("method", DEFAULT_TRAINABLE) if spec.cells else DEFAULT_TRAINABLE


def last_stage_loss(config: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """(loss name, loss parameters) of a cell's last training stage."""
    st = config["stages"][-1]
    return st["loss"], {k: v for k, v in st.items() if k not in STAGE_KEYS}


def loss_beta(config: dict[str, Any]) -> float | None:
    """The ``beta`` of the last stage's loss (UAFL's focusing exponent): the stage's value, else the
    loss's declared default; None for a loss without a beta."""
    loss, params = last_stage_loss(config)
    declared = inspect.signature(LOSSES[loss]).parameters.get("beta") if loss in LOSSES else None
    if declared is None:
        return None
    return float(params.get("beta", declared.default))


def model_value(config: dict[str, Any], key: str, kind: type, missing: Any) -> Any:
    """[model] ``key`` of a cell's config, else the network's default; ``missing`` if it has no such parameter."""
    value = config["model"].get(key, network_default(config, key))
    return missing if value is None else kind(value)


def cell_info(spec: AblationSpec) -> pd.DataFrame:
    """One row per cell (index: cell id): variant id, seed, interval, interpolation, loss, whether the loss
    has parameters, beta."""
    rows = []
    for cell in spec.cells:
        loss, params = last_stage_loss(cell.config)
        rows.append({"cell": cell.id, "variant": cell_id(variant_values(cell)),
                     "seed": cell.values.get("seed", cell.config.get("seed")),
                     "interval": model_value(cell.config, "interval", float, np.nan),
                     "interpolation": model_value(cell.config, "interpolation", str, ""),
                     "loss": loss, "loss_params": bool(params), "beta": loss_beta(cell.config)})
    return pd.DataFrame(rows).set_index("cell") if rows else pd.DataFrame()
