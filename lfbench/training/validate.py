"""Validation during training: whole-image inference on chosen scenes, BadPix and MSE x100
(lfbench.scoring.metrics) inside a border mask, per scene and pooled over the pixels of all scenes (as
the authors' validation pools its 8 scenes). Each prediction is prepared for scoring as every score is
(lfbench.scoring.prepare.SceneReference.prepare), at low resolution, on the validation crop, and scored from
its errors at the scored pixels (lfbench.scoring.pixels), as the scoring engine scores every metric."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from lfbench.data.scene import LOWRES, Scene
from lfbench.method.trainable import contract_problem, plugin_failure
from lfbench.scoring.base import Metric
from lfbench.scoring.general import bad_pix_metric
from lfbench.scoring.metrics import get_metric
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.policy import LFBENCH
from lfbench.scoring.policy import scorer as scorer_policy
from lfbench.scoring.prepare import SceneReference
from lfbench.scoring.rules import ScoringRules
from lfbench.training.data import ValidationScene, validation_size
from lfbench.utils.errors import DataError, SpecError


def check_validation_area(scenes: Sequence[Scene], border: int, max_size: int, source: str | Path | None) -> None:
    """SpecError (naming the config ``source``) before training when ``border`` (validation.border)
    leaves no pixel of a validation scene, after the validation.max_size crop, to score: its BadPix and
    MSE would be NaN at every validation."""
    for scene in scenes:
        h, w = validation_size(scene.spatial_size, max_size)
        if min(h, w) <= 2 * border:
            crop = " after validation.max_size" if (h, w) != tuple(scene.spatial_size) else ""
            raise SpecError(f"validation.border = {border} leaves no pixel of validation scene {scene.name!r} "
                            f"({w}x{h} px{crop}) to score: the border must be below {(min(h, w) + 1) // 2}", source)


@torch.no_grad()
def predict_disparity(model: torch.nn.Module, views: np.ndarray, device: torch.device, name: str = "validation"
                      ) -> np.ndarray:
    """(N, h, w) gray views -> (h, w) float32 disparity, model in eval mode, batch 1. The output is held to
    the network contract (lfbench.method.trainable.contract_problem, the one check of a prediction):
    DataError naming the validation scene ``name`` otherwise, or when the forward pass fails."""
    was_training = model.training
    model.eval()
    try:
        out = model(torch.from_numpy(views).unsqueeze(0).to(device))
    except Exception as exc:  # noqa: BLE001 - whatever the network's forward raised: one line
        raise DataError(f"validation on {name}: {plugin_failure('the network', exc)}") from None
    finally:
        model.train(was_training)
    problem = contract_problem(out, tuple(views.shape[1:]), getattr(model, "disparities", None))
    if problem:
        raise DataError(f"validation on {name}: the network breaks the network contract: {problem}")
    return out[0][0].float().cpu().numpy()


def validation_metrics(threshold: float) -> dict[str, Metric]:
    """The metrics validation logs, by their key in metrics.jsonl: ``badpix`` (BadPix at ``threshold`` px, the
    registry's metric of that threshold: lfbench.scoring.general.bad_pix_metric) and ``mse_x100``
    (lfbench.scoring.metrics), scored as the scoring engine scores them (Metric.score_pixels)."""
    return {"badpix": bad_pix_metric(threshold), "mse_x100": get_metric("mse_x100")}


def validate(model: torch.nn.Module, scenes: Sequence[ValidationScene], device: torch.device, *, border: int,
             threshold: float, scorer: str | None = None) -> dict:
    """``{"badpix": %, "mse_x100": ..., "pixels": n, "scenes": {name: {...}}}``; badpix at ``threshold`` px, both
    scored inside a ``border`` px border by the ``scorer``'s comparison and non-finite rule (lfbench.scoring.policy,
    None: lfbench's); a training run's: its [validation] section, which takes what it leaves unset from the training
    data's protocol, lfbench.training.config.ValidationConfig.of_protocol."""
    per_scene: dict[str, dict[str, float]] = {}
    gts, preds = [], []
    policy = scorer_policy(scorer or LFBENCH.name)
    rules = ScoringRules(border_px=border, scorer=policy.name)
    metrics = validation_metrics(threshold)
    for s in scenes:
        pred = predict_disparity(model, s.views, device, s.name)
        p = SceneReference.of_ground_truth(s.gt, rules, s.name).prepare(pred, LOWRES, f"validation on {s.name}")
        px = p.errors()  # the prediction's errors inside the border, as every score computes them
        per_scene[s.name] = {key: metric.score_pixels(px) for key, metric in metrics.items()}
        scored = slice(None) if policy.nan_good else px.gt_finite  # the pixels the policy scores
        gts.append(px.gt[scored])
        preds.append(px.pred[scored])
    pooled = PixelErrors.of_maps(np.concatenate(gts), np.concatenate(preds))
    pooled.scorer = policy
    return {**{key: metric.score_pixels(pooled) for key, metric in metrics.items()}, "threshold": threshold,
            "pixels": pooled.size, "scenes": per_scene}
