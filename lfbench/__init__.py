"""lfbench: light-field depth estimation on the HCI 4D Light Field Benchmark.

The public API, importable from ``lfbench`` itself:

- methods: :class:`Method`, :class:`Prediction`, :func:`register_method`, :func:`create`,
  :func:`create_from_spec`, :func:`list_methods`; trainable networks (``lfbench evaluate`` as
  ``NAME:weights=PATH``, ``train``, ``ablate``, ``bench``): :class:`Trainable`, :func:`register_trainable`,
  :func:`get_trainable`; parameter bounds for ``typing.Annotated``: :class:`Range`;
- metrics (plain functions of ``(gt, pred, mask)`` arrays): :func:`bad_pix`, :func:`mse_x100`,
  :func:`q25_x100`, :func:`bad_pix_curve`; every metric's definition by id: :func:`get_metric`,
  :func:`list_metrics`;
- data: :func:`open_dataset` (any dataset layout: the scenes of a data root), :class:`Scene` (the contract of
  a dataset's scenes, whatever its layout: a dataset's adapter is the one place that knows it), :class:`Benchmark`,
  :class:`ArrayLightField`, :func:`read_pfm`, :func:`write_pfm`;
- errors: :class:`LFBenchError`, :class:`DataError`, :class:`SpecError`.

Where things are: ``lfbench.data`` (scenes, PFM, parameters, submissions, synthetic scenes),
``lfbench.scoring`` (metrics, scoring rules, statistics, uncertainty), ``lfbench.method`` (Method,
registry), ``lfbench.results`` (results files), ``lfbench.runs`` (``folder.evaluate_to_folder``, regression,
demo, benchmarks), ``lfbench.training``, ``lfbench.ablation``, ``lfbench.reports`` (output writers,
tables, figures, the HTML report, references), ``lfbench.cli``.
"""

__version__ = "0.1.0"

from typing import TYPE_CHECKING, Any  # noqa: E402

#: Each public name and the module it comes from, imported on first use (PEP 562): ``import lfbench`` (and so
#: every ``lfbench`` command, e.g. ``lfbench evaluate --help``) starts without numpy, PIL or the registries.
_PUBLIC = {
    "read_pfm": "lfbench.data.pfm", "write_pfm": "lfbench.data.pfm",
    "ArrayLightField": "lfbench.data.scene", "Benchmark": "lfbench.data.scene", "Scene": "lfbench.data.scene",
    "open_dataset": "lfbench.data.dataset",
    "Method": "lfbench.method.base", "Prediction": "lfbench.method.base", "Range": "lfbench.method.params",
    "create": "lfbench.method.registry", "create_from_spec": "lfbench.method.registry",
    "list_methods": "lfbench.method.registry", "register_method": "lfbench.method.registry",
    "Trainable": "lfbench.method.trainable", "get_trainable": "lfbench.method.trainable",
    "register_trainable": "lfbench.method.trainable",
    "bad_pix": "lfbench.scoring.metrics", "bad_pix_curve": "lfbench.scoring.metrics",
    "get_metric": "lfbench.scoring.metrics", "list_metrics": "lfbench.scoring.metrics",
    "mse_x100": "lfbench.scoring.metrics", "q25_x100": "lfbench.scoring.metrics",
    "DataError": "lfbench.utils.errors", "LFBenchError": "lfbench.utils.errors", "SpecError": "lfbench.utils.errors",
}

__all__ = [
    "__version__",
    "Method", "Prediction", "create", "create_from_spec", "list_methods", "register_method",
    "Trainable", "register_trainable", "get_trainable", "Range",
    "bad_pix", "bad_pix_curve", "mse_x100", "q25_x100", "get_metric", "list_metrics",
    "open_dataset", "Scene", "Benchmark", "ArrayLightField", "read_pfm", "write_pfm",
    "LFBenchError", "DataError", "SpecError",
]


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use (and kept)."""
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'lfbench' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_PUBLIC})


if TYPE_CHECKING:  # what type checkers and IDEs see
    from lfbench.data.dataset import open_dataset
    from lfbench.data.pfm import read_pfm, write_pfm
    from lfbench.data.scene import ArrayLightField, Benchmark, Scene
    from lfbench.method.base import Method, Prediction
    from lfbench.method.params import Range
    from lfbench.method.registry import create, create_from_spec, list_methods, register_method
    from lfbench.method.trainable import Trainable, get_trainable, register_trainable
    from lfbench.scoring.metrics import bad_pix, bad_pix_curve, get_metric, list_metrics, mse_x100, q25_x100
    from lfbench.utils.errors import DataError, LFBenchError, SpecError
