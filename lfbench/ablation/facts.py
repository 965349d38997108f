"""What each cell of an ablation is, read from its training config: its variant and seed, the value of
any axis (a grid axis, a network parameter with the network's default where the config gives none, the
last stage's loss or one of that loss's declared parameters, lr, seed, a dotted config key), and its last
stage's loss. Shared by the report, the significance tests and the baseline verdicts (all above this
module: it imports none of them)."""

from __future__ import annotations

import inspect
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from lfbench.ablation.spec import AblationSpec, cell_id, network_default, network_name, variant_values
from lfbench.training.config import STAGE_KEYS
from lfbench.training.losses import LOSSES

__all__ = ["axis_text", "axis_value", "cell_info", "last_stage_loss", "loss_param", "model_value", "network_of",
           "same_value"]


def network_of(spec: AblationSpec) -> str:
    """The registered trainable network the spec's cells train (the default network without cells)."""
    return network_name(spec.cells[0].config if spec.cells else {})


def last_stage_loss(config: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """(loss name, loss parameters) of a cell's last training stage."""
    st = config["stages"][-1]
    return st["loss"], {k: v for k, v in st.items() if k not in STAGE_KEYS}


def loss_param(config: dict[str, Any], name: str) -> Any:
    """The parameter ``name`` of the last stage's loss (e.g. a focusing exponent): the stage's value, else the
    loss's declared default (a number as float); None for a loss without such a parameter."""
    loss, params = last_stage_loss(config)
    declared = dict(list(inspect.signature(LOSSES[loss]).parameters.items())[4:]).get(name) if loss in LOSSES else None
    if declared is None:
        return None
    value = params.get(name, declared.default)
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else value


def model_value(config: dict[str, Any], key: str, kind: type, missing: Any) -> Any:
    """[model] ``key`` of a cell's config, else the network's default; ``missing`` if it has no such parameter."""
    value = config["model"].get(key, network_default(config, key))
    return missing if value is None else kind(value)


def axis_value(config: dict[str, Any], axis: str) -> Any:
    """A cell's value of ``axis``: ``loss`` (the last stage's loss name), a parameter of that loss (its
    declared default when unset; None when the loss has no such parameter), ``lr`` (the last stage's),
    ``seed``, a network parameter (the network's default when unset), or a dotted config key; None when
    the cell has none."""
    if axis == "loss":
        return last_stage_loss(config)[0]
    if axis == "lr":
        return config["stages"][-1].get("lr")
    if axis == "seed":
        return config.get("seed")
    if "." in axis:
        node: Any = config
        for part in axis.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        return node
    if axis in config["model"] or network_default(config, axis) is not None:
        return config["model"].get(axis, network_default(config, axis))
    return loss_param(config, axis)


def axis_text(config: dict[str, Any], axis: str) -> str:
    """How a table shows a cell's ``axis``: a number as ``:g``, the loss with its parameters
    (``uafl(beta=0.5)``), '-' when the cell has none."""
    if axis == "loss":
        loss, params = last_stage_loss(config)
        return loss + ("" if not params else "(" + ", ".join(f"{k}={v}" for k, v in params.items()) + ")")
    return _text(axis_value(config, axis))


def _text(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, float | int) and not isinstance(value, bool):
        return f"{value:g}"
    return str(value)


def same_value(value: Any, text: Any) -> bool:
    """Whether a cell's value equals a declared one (numbers within 1e-9, other values as stripped text)."""
    try:
        return bool(np.isclose(float(value), float(text), rtol=0, atol=1e-9))
    except (TypeError, ValueError):
        return str(value).strip() == str(text).strip()


def cell_info(spec: AblationSpec, axes: Sequence[str] = ()) -> pd.DataFrame:
    """One row per cell (index: cell id): variant id, seed, loss, whether the loss has parameters, and the
    value of each of ``axes`` (:func:`axis_value`; NaN when the cell has none)."""
    rows = []
    for cell in spec.cells:
        loss, params = last_stage_loss(cell.config)
        row = {"cell": cell.id, "variant": cell_id(variant_values(cell)),
               "seed": cell.values.get("seed", cell.config.get("seed")), "loss": loss, "loss_params": bool(params)}
        for axis in axes:
            value = axis_value(cell.config, axis)
            row[axis] = np.nan if value is None else value
        rows.append(row)
    return pd.DataFrame(rows).set_index("cell") if rows else pd.DataFrame()
