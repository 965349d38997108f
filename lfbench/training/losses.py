"""Training losses of SubFocal and its ablations, as pure functions of tensors.

Every loss takes ``(disparity, prob, target, disparities)``:

- disparity: (B, H, W) predicted disparity in px per view step (the softmax regression
  ``sum_k p_k d_k``);
- prob: (B, D, H, W) predicted probability over the candidate disparities (softmax over D);
- target: (B, H, W) ground-truth disparity in px per view step;
- disparities: (D,) the candidate disparities, evenly spaced (d_min, d_min + interval, ...);

and returns a scalar: the mean over all pixels. Definitions follow the SubFocal authors' public code
(summarised in docs/subfocal-training.md, "Losses and schedule"):

- target distribution: ``t = d - d_min``, ``l = floor(t / interval)``, ``r = l + 1``,
  ``w_l = (r * interval - t) / interval``, ``w_r = (t - l * interval) / interval`` on bins l and r;
  a bin outside 0..D-1 gets nothing (like ``tf.one_hot`` of an out-of-range index);
- KL(p || q) = sum_k clip(p_k) ln(clip(p_k) / clip(q_k)), clip to [1e-7, 1] (Keras ``kl_divergence``);
- JS(P || T) = 0.5 [KL(P || M) + KL(T || M)], M = (P + T) / 2 (M is formed before clipping);
- U = clip(JS(P || T), 1e-7, 1); UAFL(beta) = mean(U^beta * |d - d_hat|), U not detached.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable

import torch

from lfbench.utils.errors import SpecError
from lfbench.utils.registry import Registry

EPSILON = 1e-7  # Keras backend epsilon: the clipping bound of probabilities and of U

LossFn = Callable[..., torch.Tensor]

__all__ = [
    "EPSILON",
    "target_distribution",
    "kl_divergence",
    "js_divergence",
    "uncertainty",
    "l1_loss",
    "mse_loss",
    "js_loss",
    "kl_loss",
    "l1_js_loss",
    "l1_kl_loss",
    "uafl_loss",
    "LOSSES",
    "make_loss",
]


def _interval(disparities: torch.Tensor) -> torch.Tensor:
    if disparities.dim() != 1 or disparities.numel() < 2:
        raise ValueError(f"disparities must be (D,) with D >= 2, got {tuple(disparities.shape)}")
    return (disparities[-1] - disparities[0]) / (disparities.numel() - 1)


def target_distribution(target: torch.Tensor, disparities: torch.Tensor) -> torch.Tensor:
    """(B, H, W) disparity -> (B, D, H, W) weights on the two neighbouring candidate bins.

    Inside [d_min, d_max] the weights sum to 1 and their mean sum_k T_k d_k equals the target;
    a neighbour outside the grid gets nothing, so a target beyond the range loses that share.
    """
    disparities = disparities.to(device=target.device, dtype=target.dtype)
    interval = _interval(disparities)
    t = target - disparities[0]
    left = torch.floor(t / interval)
    right = left + 1
    w_left = (right * interval - t) / interval
    w_right = (t - left * interval) / interval
    bins = torch.arange(disparities.numel(), device=target.device, dtype=target.dtype).view(1, -1, 1, 1)
    left, right = left.unsqueeze(1), right.unsqueeze(1)
    zero = target.new_zeros(())
    return (torch.where(bins == left, w_left.unsqueeze(1), zero)
            + torch.where(bins == right, w_right.unsqueeze(1), zero))


def kl_divergence(p: torch.Tensor, q: torch.Tensor, dim: int = 1) -> torch.Tensor:
    """Keras ``kl_divergence(p, q)``: sum over ``dim`` of clip(p) ln(clip(p) / clip(q)), clip to [1e-7, 1]."""
    p = p.clamp(EPSILON, 1.0)
    q = q.clamp(EPSILON, 1.0)
    return (p * torch.log(p / q)).sum(dim=dim)


def js_divergence(p: torch.Tensor, q: torch.Tensor, dim: int = 1) -> torch.Tensor:
    """Jensen-Shannon divergence 0.5 [KL(p || m) + KL(q || m)], m = (p + q) / 2, natural log (nats)."""
    m = 0.5 * (p + q)
    return 0.5 * (kl_divergence(p, m, dim) + kl_divergence(q, m, dim))


def uncertainty(prob: torch.Tensor, target: torch.Tensor, disparities: torch.Tensor) -> torch.Tensor:
    """U = clip(JS(P || T), 1e-7, 1): (B, H, W), differentiable with respect to ``prob``."""
    return js_divergence(prob, target_distribution(target, disparities)).clamp(EPSILON, 1.0)


def l1_loss(disparity: torch.Tensor, prob: torch.Tensor | None, target: torch.Tensor,
            disparities: torch.Tensor | None = None) -> torch.Tensor:
    """Mean absolute disparity error (px): the authors' stage-1 'mae'."""
    return (disparity - target).abs().mean()


def mse_loss(disparity: torch.Tensor, prob: torch.Tensor | None, target: torch.Tensor,
             disparities: torch.Tensor | None = None) -> torch.Tensor:
    """Mean squared disparity error (px^2)."""
    return (disparity - target).square().mean()


def js_loss(disparity: torch.Tensor, prob: torch.Tensor, target: torch.Tensor,
            disparities: torch.Tensor) -> torch.Tensor:
    """Mean over pixels of JS(P || T) (nats)."""
    return js_divergence(prob, target_distribution(target, disparities)).mean()


def kl_loss(disparity: torch.Tensor, prob: torch.Tensor, target: torch.Tensor,
            disparities: torch.Tensor) -> torch.Tensor:
    """Mean over pixels of KL(T || P) (Keras ``KLDivergence(y_true=T, y_pred=P)``)."""
    return kl_divergence(target_distribution(target, disparities), prob).mean()


def l1_js_loss(disparity: torch.Tensor, prob: torch.Tensor, target: torch.Tensor,
               disparities: torch.Tensor) -> torch.Tensor:
    """L1 + JS, equal weights."""
    return l1_loss(disparity, prob, target) + js_loss(disparity, prob, target, disparities)


def l1_kl_loss(disparity: torch.Tensor, prob: torch.Tensor, target: torch.Tensor,
               disparities: torch.Tensor) -> torch.Tensor:
    """L1 + KL, equal weights."""
    return l1_loss(disparity, prob, target) + kl_loss(disparity, prob, target, disparities)


def uafl_loss(disparity: torch.Tensor, prob: torch.Tensor, target: torch.Tensor, disparities: torch.Tensor,
              beta: float = 0.1) -> torch.Tensor:
    """Uncertainty-aware focal loss: mean of U^beta * |d - d_hat|; U is not detached (beta = 0 is L1)."""
    u = uncertainty(prob, target, disparities)
    return (u.pow(beta) * (disparity - target).abs()).mean()


#: Every loss by name (the generic registry: "Unknown loss 'x'. Available: ..." for another name).
LOSSES: Registry[LossFn] = Registry("loss")
for _name, _fn in (("l1", l1_loss), ("mse", mse_loss), ("js", js_loss), ("kl", kl_loss), ("l1+js", l1_js_loss),
                   ("l1+kl", l1_kl_loss), ("uafl", uafl_loss)):
    LOSSES.add(_name, _fn)

# Losses that need the probability volume (the others use the disparity alone).
NEEDS_DISTRIBUTION = frozenset({"js", "kl", "l1+js", "l1+kl", "uafl"})


def make_loss(name: str, **params) -> LossFn:
    """The loss ``name`` (see LOSSES) with its keyword parameters bound, e.g. ``make_loss("uafl", beta=0.1)``.

    SpecError for an unknown name or parameter.
    """
    key = name.strip().lower()
    fn = LOSSES.get(key)
    accepted = set(list(inspect.signature(fn).parameters)[4:])
    unknown = set(params) - accepted
    if unknown:
        allowed = ", ".join(sorted(accepted)) or "none"
        raise SpecError(f"loss {key!r} has no parameter {', '.join(sorted(unknown))} (parameters: {allowed})")
    for k, v in params.items():  # every loss parameter (beta) is an exponent or weight: a finite number >= 0
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
            raise SpecError(f"loss {key!r}: {k} must be a finite number >= 0, got {str(v)[:40]!r}")
    if not params:
        return fn

    def bound(disparity, prob, target, disparities):
        return fn(disparity, prob, target, disparities, **params)

    bound.__name__ = f"{fn.__name__}({', '.join(f'{k}={v}' for k, v in params.items())})"
    return bound
