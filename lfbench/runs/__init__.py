"""Runs: methods run on scenes and scored (runner) into a folder with the chosen output writers
(folder: :func:`evaluate_to_folder`), golden regression checks (regress), the offline demo (demo) and
speed/memory benchmarks (bench). The results data model is :mod:`lfbench.results` (also importable as
``lfbench.runs.results``)."""

from lfbench.results import Results
from lfbench.runs.folder import CIOptions, evaluate_to_folder

__all__ = ["CIOptions", "Results", "evaluate_to_folder"]
