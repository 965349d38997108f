"""The benchmark's scoring rules: which resolution each number is scored at, the border, the non-finite rule.

Rules (the official toolkit's; docs/benchmark-rules.md, General metrics): a 15 px border is ignored
(scaled with resolution); backgammon, dots and stripes (:func:`benchmark_highres_scenes`) are scored at
high resolution when ``gt_disp_highres.pfm`` exists (the 512x512 prediction upsampled x10 by nearest
neighbour exactly as ``scipy.ndimage.zoom(order=0)``, border 150 px), otherwise at low resolution; the
resolution is recorded beside every number. Region and stratified metrics
(lfbench.scoring.region_metrics) are scored wherever their mask files exist, at their own resolution (see
:func:`metric_resolution`). A scene's valid_mask.png (low resolution; any other size is refused) leaves its
False pixels out of every metric at every resolution, upsampled to high resolution exactly as predictions
are, missed dots included. Predictions cropped symmetrically by a border (482x482, 490x490) are aligned
to the centre.

How a prediction is made ready under these rules is :mod:`lfbench.scoring.prepare` (one place); scoring
a scene with them, :func:`lfbench.scoring.score.score_scene`. This module needs only the
:class:`~lfbench.scoring.base.Metric` type.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from lfbench.data.dataset import DATASETS, DatasetProtocol
from lfbench.data.disparity import EVALUATION_BORDER_PX
from lfbench.data.scene import HIGHRES, LOWRES, Scene
from lfbench.scoring.base import Metric
from lfbench.scoring.policy import SCORERS
from lfbench.utils.errors import DataError

__all__ = ["BENCHMARK_DATASET", "ScoringRules", "benchmark_highres_scenes", "metric_resolution"]

#: The dataset adapter (lfbench.data.dataset.DATASETS) of the benchmark whose rules are the defaults: the HCI 4D
#: Light Field Benchmark, how the paper's numbers were scored.
BENCHMARK_DATASET = "hci"


@functools.cache
def benchmark_highres_scenes() -> frozenset[str]:
    """The scenes the benchmark scores at high resolution (where their high-resolution ground truth exists):
    the default of :attr:`ScoringRules.highres_scenes`, as the protocol of the benchmark's adapter
    (:data:`BENCHMARK_DATASET`) declares them; other datasets feed theirs through their protocol
    (:meth:`ScoringRules.of_protocol`)."""
    return DATASETS.get(BENCHMARK_DATASET).protocol.highres_scenes


@dataclass(frozen=True)
class ScoringRules:
    """How a scene is scored. Defaults are the benchmark's."""

    border_px: int = EVALUATION_BORDER_PX
    highres_scenes: frozenset[str] = field(default_factory=benchmark_highres_scenes)
    toolkit: bool = False  # reproduce the toolkit's non-finite handling exactly
    allow_highres: bool = True  # False: score everything at low resolution
    scorer: str = "lfbench"  # BadPix's comparison and the non-finite policy (lfbench.scoring.policy)

    def to_meta(self) -> dict[str, Any]:
        """The rules as a results file records them (``meta["scoring"]``); ``allow_highres`` is not
        recorded: every number carries its resolution."""
        meta = {"border_px": self.border_px, "toolkit_nonfinite": self.toolkit,
                "highres_scenes": sorted(self.highres_scenes)}
        return meta if self.scorer == "lfbench" else {**meta, "scorer": self.scorer}

    @classmethod
    def of_protocol(cls, protocol: DatasetProtocol, *, toolkit: bool = False,
                    allow_highres: bool = True) -> ScoringRules:
        """The rules of a dataset's scoring protocol (lfbench.data.dataset.DatasetProtocol): its border and
        its high-resolution scenes (scored at high resolution only where the protocol has that resolution)."""
        return cls(border_px=protocol.border_px, highres_scenes=protocol.highres_scenes, toolkit=toolkit,
                   allow_highres=allow_highres and HIGHRES in protocol.resolutions, scorer=protocol.scorer)

    @classmethod
    def from_meta(cls, meta: Mapping[str, Any], **overrides: Any) -> ScoringRules:
        """The rules a results file was scored under, from its ``meta["scoring"]`` (:meth:`to_meta`);
        what it does not record keeps the default. ``overrides``: fields set by the caller (e.g.
        ``allow_highres``). ValueError naming the key when a recorded value has the wrong type (a results
        file from elsewhere is untrusted)."""
        scoring = meta.get("scoring")
        if scoring is None:
            scoring = {}
        if not isinstance(scoring, Mapping):
            raise ValueError("'scoring' must be an object")
        recorded: dict[str, Any] = {}
        if "border_px" in scoring:
            border = scoring["border_px"]
            if isinstance(border, bool) or not isinstance(border, int) or border < 0:
                raise ValueError("'scoring.border_px' must be an integer >= 0")
            recorded["border_px"] = border
        if "highres_scenes" in scoring:
            scenes = scoring["highres_scenes"]
            if not isinstance(scenes, list) or not all(isinstance(name, str) for name in scenes):
                raise ValueError("'scoring.highres_scenes' must be a list of scene names")
            recorded["highres_scenes"] = frozenset(scenes)
        if "toolkit_nonfinite" in scoring:
            if not isinstance(scoring["toolkit_nonfinite"], bool):
                raise ValueError("'scoring.toolkit_nonfinite' must be true or false")
            recorded["toolkit"] = scoring["toolkit_nonfinite"]
        if "scorer" in scoring:
            if scoring["scorer"] not in SCORERS:
                raise ValueError(f"'scoring.scorer' must be one of {', '.join(SCORERS)}")
            recorded["scorer"] = scoring["scorer"]
        return cls(**{**recorded, **overrides})

    def check_border(self, scenes: Iterable[Scene]) -> None:
        """DataError naming the first scene of ``scenes`` whose views the border leaves no pixel of (2 x border
        >= its height or width at low resolution; high resolution scales both): refused before any scoring,
        never a table of empty values."""
        for scene in scenes:
            if not isinstance(scene, Scene):
                continue
            h, w = scene.spatial_size
            if 2 * self.border_px >= min(h, w):
                raise DataError(f"the scoring border of {self.border_px} px (the dataset's protocol) leaves no pixel "
                                f"of this scene's {w}x{h} px views to score", scene.path)

    def general_resolution(self, scene: Scene) -> str:
        """'highres' for the benchmark's high-resolution scenes when their gt exists, else 'lowres'.
        ``scene``: a Scene, or anything that answers ``name`` and ``has_gt`` as it does (a
        :class:`~lfbench.scoring.prepare.SceneReference`)."""
        if self.allow_highres and scene.name in self.highres_scenes and scene.has_gt(HIGHRES):
            return HIGHRES
        return LOWRES


def metric_resolution(scene: Scene, metric: Metric, rules: ScoringRules = ScoringRules()) -> str | None:
    """The resolution ``metric`` is scored at on ``scene``, or None when it does not apply.

    General metrics ('scene'): the scene's rule. A 'highres' metric: high resolution when
    high-res scoring is allowed and the high-res gt and all its masks exist, else low resolution
    (recorded as such) when its low-res masks exist, else None. A 'lowres' metric: low resolution
    when its low-res masks exist, else None. ``scene``: a Scene, or anything that answers ``name``,
    ``has_gt`` and ``mask_names`` as it does (a :class:`~lfbench.scoring.prepare.SceneReference`).
    """
    if metric.resolution == "scene":
        return rules.general_resolution(scene)
    needed = metric.required_masks

    def has_masks(res: str) -> bool:
        present = set(scene.mask_names(res)) if needed else set()
        return all(name in present for name in needed)

    if metric.resolution == HIGHRES and rules.allow_highres and scene.has_gt(HIGHRES) and has_masks(HIGHRES):
        return HIGHRES
    return LOWRES if has_masks(LOWRES) else None
