"""The results data model, importable under its earlier name: it is :mod:`lfbench.results` (one layer
below the reports that read it and the runs that write it)."""

from lfbench.results import CSV_COLUMNS, Record, Results, RunInfo, check_names

__all__ = ["CSV_COLUMNS", "Record", "Results", "RunInfo", "check_names"]
