"""lfbench: light-field depth estimation on the HCI 4D Light Field Benchmark.

The public API, importable from ``lfbench`` itself:

- methods: :class:`Method`, :class:`Prediction`, :func:`register_method`, :func:`create`,
  :func:`create_from_spec`, :func:`list_methods`; trainable networks (``lfbench evaluate`` as
  ``NAME:weights=PATH``, ``train``, ``ablate``, ``bench``): :class:`Trainable`, :func:`register_trainable`,
  :func:`get_trainable`; parameter bounds for ``typing.Annotated``: :class:`Range`;
- metrics (plain functions of ``(gt, pred, mask)`` arrays): :func:`bad_pix`, :func:`mse_x100`,
  :func:`q25_x100`, :func:`bad_pix_curve`; every metric's definition by id: :func:`get_metric`,
  :func:`list_metrics`;
- data: :class:`Scene`, :class:`Benchmark`, :class:`ArrayLightField`, :func:`read_pfm`, :func:`write_pfm`;
- errors: :class:`LFBenchError`, :class:`DataError`, :class:`SpecError`.

Where things are: ``lfbench.data`` (scenes, PFM, parameters, submissions, synthetic scenes),
``lfbench.scoring`` (metrics, scoring rules, statistics, uncertainty), ``lfbench.method`` (Method,
registry), ``lfbench.results`` (results files), ``lfbench.runs`` (``folder.evaluate_to_folder``, regression,
demo, benchmarks), ``lfbench.training``, ``lfbench.ablation``, ``lfbench.reports`` (output writers,
tables, figures, the HTML report, references), ``lfbench.cli``.
"""

__version__ = "0.1.0"

from lfbench.data.pfm import read_pfm, write_pfm  # noqa: E402
from lfbench.data.scene import ArrayLightField, Benchmark, Scene  # noqa: E402
from lfbench.method.base import Method, Prediction  # noqa: E402
from lfbench.method.params import Range  # noqa: E402
from lfbench.method.registry import create, create_from_spec, list_methods, register_method  # noqa: E402
from lfbench.method.trainable import Trainable, get_trainable, register_trainable  # noqa: E402
from lfbench.scoring.metrics import bad_pix, bad_pix_curve, get_metric, list_metrics, mse_x100, q25_x100  # noqa: E402
from lfbench.utils.errors import DataError, LFBenchError, SpecError  # noqa: E402

__all__ = [
    "__version__",
    "Method", "Prediction", "create", "create_from_spec", "list_methods", "register_method",
    "Trainable", "register_trainable", "get_trainable", "Range",
    "bad_pix", "bad_pix_curve", "mse_x100", "q25_x100", "get_metric", "list_metrics",
    "Scene", "Benchmark", "ArrayLightField", "read_pfm", "write_pfm",
    "LFBenchError", "DataError", "SpecError",
]
