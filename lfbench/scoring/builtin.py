"""The benchmark's own metrics, registered through the entry-point group ``lfbench.metrics`` as a plugin's are
(pyproject.toml: ``hci = "lfbench.scoring.builtin"``): the general and runtime metrics, the region metrics, the
stratified metrics of each stratified scene, in this order, and the families ``badpix_<t>`` and ``q<p>_x100``.
"""

from __future__ import annotations

from lfbench.scoring.general import GENERAL_METRICS, RUNTIME_METRICS, badpix_family, quantile_family
from lfbench.scoring.metrics import METRICS
from lfbench.scoring.region_metrics import REGION_METRICS, STRATIFIED_METRICS

__all__: list[str] = []

for _m in (*GENERAL_METRICS, *RUNTIME_METRICS, *REGION_METRICS, *(m for ms in STRATIFIED_METRICS.values() for m in ms)):
    METRICS.register(_m)
METRICS.register_family("badpix_<t>", badpix_family)
METRICS.register_family("q<p>_x100", quantile_family)
