"""lfbench: light-field depth estimation on the HCI 4D Light Field Benchmark.

Benchmark-exact metrics (:mod:`lfbench.metrics`), scenes (:mod:`lfbench.scene`), a method registry
(:mod:`lfbench.registry`), reports and a CLI (``lfbench``).
"""

__version__ = "0.1.0"

from lfbench.errors import DataError, LFBenchError, SpecError  # noqa: E402
from lfbench.registry import create, create_from_spec, list_methods, register_method  # noqa: E402

__all__ = ["__version__", "create", "create_from_spec", "list_methods", "register_method",
           "LFBenchError", "DataError", "SpecError"]
