"""Training checkpoints and exported weights: written atomically with torch.save, read by the method
layer's one reader (:func:`lfbench.method.checkpoint.read_checkpoint`: ``torch.load(weights_only=True)``,
so every value is a tensor, number, string, list or dict).

A training checkpoint holds the model and optimizer state, the stage index and the number of
steps done in it, the RNG states of python, numpy and torch, and the resolved config. Exported
weights are what inference loads: ``{"state_dict", "config": net.config(), "training": {...}}``.
"""

from __future__ import annotations

import hashlib
import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lfbench.method.checkpoint import CHECKPOINT_FORMAT, WEIGHTS_FORMAT, read_checkpoint
from lfbench.utils.atomic import atomic_open
from lfbench.utils.errors import DataError, LFBenchError

VERSION = 1


def rng_state() -> dict[str, Any]:
    """Python, numpy (global) and torch RNG states as weights-only-loadable values."""
    version, internal, gauss = random.getstate()
    kind, keys, pos, has_gauss, cached = np.random.get_state(legacy=True)  # type: ignore[misc]
    state: dict[str, Any] = {
        "python": [version, torch.tensor(internal, dtype=torch.int64), gauss],
        "numpy": [kind, torch.from_numpy(np.asarray(keys, dtype=np.int64)), int(pos), int(has_gauss), float(cached)],
        "torch": torch.get_rng_state(),
    }
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    """Restore what :func:`rng_state` saved."""
    version, internal, gauss = state["python"]
    random.setstate((int(version), tuple(int(x) for x in internal.tolist()), gauss))
    kind, keys, pos, has_gauss, cached = state["numpy"]
    np.random.set_state((kind, keys.numpy().astype(np.uint32), int(pos), int(has_gauss), float(cached)))
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available() and len(state["cuda"]) == torch.cuda.device_count():
        torch.cuda.set_rng_state_all(state["cuda"])


def save(path: str | Path, payload: dict[str, Any]) -> None:
    """torch.save ``payload`` to ``path`` atomically (a reader sees the old file or the new one); a write
    error (disk full, read-only folder) is one LFBenchError naming the file, and the old file stays."""
    try:
        with atomic_open(path, "wb") as f:
            torch.save(payload, f)
    except (OSError, RuntimeError) as exc:  # torch reports a failed write of its zip stream as RuntimeError
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else " ".join(str(exc).split())[:120]
        raise LFBenchError(f"cannot write checkpoint: {reason} (the previous one is kept)", path) from None


def load(path: str | Path, expected_format: str | None = None) -> dict[str, Any]:
    """The payload of a checkpoint (:func:`~lfbench.method.checkpoint.read_checkpoint`); DataError naming the
    file if it is unreadable, not a torch checkpoint or, with ``expected_format``, of another format."""
    payload = read_checkpoint(path)
    if expected_format is not None and payload.get("format") != expected_format:
        raise DataError(f"not a {expected_format} file (format {payload.get('format')!r})", path)
    return payload


def state_sha256(state_dict: dict[str, torch.Tensor]) -> str:
    """SHA-256 over names and bytes of a state dict, in its order (an exact-equality fingerprint)."""
    h = hashlib.sha256()
    for name, t in state_dict.items():
        h.update(name.encode())
        h.update(t.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def parameters_sha256(module: torch.nn.Module) -> str:
    """:func:`state_sha256` of the module's parameters (no buffers), in named_parameters order."""
    return state_sha256(dict(module.named_parameters()))


def export_weights(path: str | Path, model: torch.nn.Module, training: dict[str, Any] | None = None,
                   method: str = "", config: dict[str, Any] | None = None) -> None:
    """Write the inference format ``{"format", "method", "state_dict", "config", "training"}`` atomically:
    ``method`` runs it as ``method:weights=PATH``; ``config`` (default ``model.config()``) rebuilds the network."""
    if config is None:
        config = model.config() if hasattr(model, "config") else {}
    save(path, {"format": WEIGHTS_FORMAT, "version": VERSION, "method": method,
                "state_dict": {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()},
                "config": config, "training": training or {}})


__all__ = ["CHECKPOINT_FORMAT", "WEIGHTS_FORMAT", "VERSION", "rng_state", "set_rng_state", "save", "load",
           "state_sha256", "parameters_sha256", "export_weights"]
