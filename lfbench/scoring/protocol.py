"""A dataset's scoring protocol made ready to score with, in one place: the rules (border, high-resolution
scenes), the metrics it scores and the disparity grid methods search (lfbench.data.dataset.DatasetProtocol).
``lfbench evaluate``, the ablation's cells and extra methods, and its report all take them from here."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from lfbench.data.dataset import DatasetProtocol, method_range_params
from lfbench.scoring.base import Metric
from lfbench.scoring.metrics import badpix_threshold, metric_order, scored_metrics
from lfbench.scoring.rules import ScoringRules

__all__ = ["Scoring", "badpix_thresholds", "protocol_scoring"]


@dataclass(frozen=True)
class Scoring:
    """How one dataset's scenes are scored: ``rules``, ``metrics`` (exactly the protocol's, then those asked for:
    lfbench.scoring.metrics.scored_metrics) and ``grid``, the ``defaults`` hook that gives a method the
    protocol's disparity range and interval (lfbench.data.dataset.method_range_params)."""

    protocol: DatasetProtocol
    rules: ScoringRules
    metrics: tuple[Metric, ...]
    grid: Callable[[Any, dict[str, Any]], dict[str, float]]

    def meta(self) -> dict[str, Any]:
        """What a results file records of the protocol besides its rules: the ids of the metrics it declares, in
        its order (``protocol_metrics``: the tables show those)."""
        return {"protocol_metrics": list(self.protocol.metrics)}


def protocol_scoring(protocol: DatasetProtocol, *, toolkit: bool = False, allow_highres: bool = True,
                     extra: Iterable[str] = ()) -> Scoring:
    """The :class:`Scoring` of ``protocol``; ``toolkit``: the toolkit's non-finite handling; ``allow_highres``:
    False scores everything at low resolution; ``extra``: metric ids asked for besides the protocol's
    (``lfbench evaluate --metrics``). DataError naming the protocol's file for a metric id that is not
    a general metric."""
    return Scoring(protocol=protocol,
                   rules=ScoringRules.of_protocol(protocol, toolkit=toolkit, allow_highres=allow_highres),
                   metrics=tuple(scored_metrics(protocol.metrics, protocol.source, extra)),
                   grid=method_range_params(protocol.disparity_range, protocol.disparity_interval))


def badpix_thresholds(metric_ids: Iterable[str]) -> list[float]:
    """The thresholds (px) of the general BadPix metrics among ``metric_ids`` (a protocol's), in table order
    (lfbench.scoring.metrics.metric_order: BadPix 0.07 first where scored): the first is the protocol's primary
    BadPix (what training validation scores unless its config says otherwise)."""
    thresholds = (badpix_threshold(metric_id) for metric_id in metric_order(metric_ids))
    return [t for t in thresholds if t is not None]
