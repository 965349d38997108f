"""Runs: methods run on scenes and scored (runner) into a folder (folder: :func:`evaluate_to_folder`),
their records (results), golden regression checks (regress), the offline demo (demo) and
speed/memory benchmarks (bench)."""

from __future__ import annotations

from typing import Any

__all__ = ["CIOptions", "Results", "evaluate_to_folder"]


def __getattr__(name: str) -> Any:  # imported on first use: ``import lfbench.runs.results`` stays light
    if name in ("CIOptions", "evaluate_to_folder"):
        from lfbench.runs import folder

        return getattr(folder, name)
    if name == "Results":
        from lfbench.runs.results import Results

        return Results
    raise AttributeError(f"module 'lfbench.runs' has no attribute {name!r}")
