"""Losses against values derived by hand from the definitions in docs/subfocal-training.md."""

from __future__ import annotations

import math

import pytest
import torch

from lfbench.training.losses import (
    EPSILON,
    LOSSES,
    js_divergence,
    kl_divergence,
    make_loss,
    target_distribution,
    uafl_loss,
    uncertainty,
)
from lfbench.utils.errors import SpecError

GRID_1 = torch.tensor([-1.0, 0.0, 1.0])  # interval 1
GRID_05 = torch.linspace(-4, 4, 17)  # the paper's grid, interval 0.5


def _pixel(values) -> torch.Tensor:
    """A (1, D, 1, 1) probability volume from a list of D values."""
    return torch.tensor(values, dtype=torch.float64).view(1, -1, 1, 1)


def _scalar(x: float) -> torch.Tensor:
    return torch.tensor(x, dtype=torch.float64).view(1, 1, 1)


# --------------------------------------------------------------------------- target distribution

def test_target_distribution_interval_1_by_hand():
    # t = 0.25 - (-1) = 1.25; l = 1, r = 2; w_l = (2 - 1.25) / 1 = 0.75, w_r = 0.25
    t = target_distribution(_scalar(0.25), GRID_1)
    assert t.shape == (1, 3, 1, 1)
    torch.testing.assert_close(t.flatten(), torch.tensor([0.0, 0.75, 0.25], dtype=torch.float64))


def test_target_distribution_interval_half_by_hand():
    # 1.3 on [-4, 4] step 0.5: t = 5.3, l = floor(10.6) = 10 (d = 1.0), r = 11 (d = 1.5);
    # w_l = (11 * 0.5 - 5.3) / 0.5 = 0.4, w_r = (5.3 - 10 * 0.5) / 0.5 = 0.6
    t = target_distribution(_scalar(1.3), GRID_05).flatten()
    expected = torch.zeros(17, dtype=torch.float64)
    expected[10], expected[11] = 0.4, 0.6
    torch.testing.assert_close(t, expected)


def test_target_distribution_on_a_bin_and_out_of_range():
    grid = GRID_05.double()
    # exactly on the bin d = 0.5 (index 9): all weight there
    t = target_distribution(_scalar(0.5), grid).flatten()
    assert t[9] == 1.0 and t.sum() == 1.0
    # d_max = 4: l = 16 gets 1, r = 17 is outside and gets nothing
    t = target_distribution(_scalar(4.0), grid).flatten()
    assert t[16] == 1.0 and t.sum() == 1.0
    # 4.2: l = 16 gets (8.5 - 8.2) / 0.5 = 0.6, the outside bin's 0.4 is lost
    t = target_distribution(_scalar(4.2), grid).flatten()
    assert t[16].item() == pytest.approx(0.6) and t.sum().item() == pytest.approx(0.6)
    # -4.3: l = -1 is outside, r = 0 gets (-0.3 + 0.5) / 0.5 = 0.4
    t = target_distribution(_scalar(-4.3), grid).flatten()
    assert t[0].item() == pytest.approx(0.4) and t.sum().item() == pytest.approx(0.4)
    # far outside: nothing at all
    assert target_distribution(_scalar(-7.0), grid).sum() == 0


@pytest.mark.parametrize("interval", [1.0, 0.5, 0.25, 0.1, 0.3])
def test_target_distribution_mean_equals_target(interval):
    grid = torch.arange(0, int(round(8 / interval)) + 1, dtype=torch.float64) * interval - 4.0
    d_max = grid[-1].item()
    gen = torch.Generator().manual_seed(0)
    target = (torch.rand(2, 5, 7, generator=gen, dtype=torch.float64) * (d_max + 4.0) - 4.0)
    t = target_distribution(target, grid)
    assert t.shape == (2, grid.numel(), 5, 7)
    assert (t >= 0).all() and (t <= 1).all()
    assert ((t > 0).sum(dim=1) <= 2).all()  # at most two neighbouring bins
    torch.testing.assert_close(t.sum(dim=1), torch.ones_like(target))
    torch.testing.assert_close((t * grid.view(1, -1, 1, 1)).sum(dim=1), target)


# --------------------------------------------------------------------------- divergences

def test_kl_and_js_by_hand():
    p = _pixel([0.2, 0.5, 0.3])
    t = target_distribution(_scalar(0.25), GRID_1.double())  # [0, 0.75, 0.25]
    # M = (P + T) / 2 = [0.1, 0.625, 0.275]
    kl_pm = 0.2 * math.log(0.2 / 0.1) + 0.5 * math.log(0.5 / 0.625) + 0.3 * math.log(0.3 / 0.275)
    # T's zero bin is clipped to 1e-7 before the log: 1e-7 * ln(1e-7 / 0.1)
    kl_tm = EPSILON * math.log(EPSILON / 0.1) + 0.75 * math.log(0.75 / 0.625) + 0.25 * math.log(0.25 / 0.275)
    m = _pixel([0.1, 0.625, 0.275])
    assert kl_divergence(p, m).item() == pytest.approx(kl_pm, rel=1e-12)
    assert kl_divergence(t, m).item() == pytest.approx(kl_tm, rel=1e-12)
    js = 0.5 * (kl_pm + kl_tm)
    assert js_divergence(p, t).item() == pytest.approx(js, rel=1e-12)
    # 0.5 * (0.053161 + 0.112912): the number itself, worked out on paper
    assert js == pytest.approx(0.0830367, abs=1e-6)
    assert uncertainty(p, _scalar(0.25), GRID_1.double()).item() == pytest.approx(js, rel=1e-12)


def test_uncertainty_is_clipped():
    # P == T: JS = 0, clipped up to 1e-7
    p = _pixel([0.0, 0.75, 0.25])
    assert uncertainty(p, _scalar(0.25), GRID_1.double()).item() == pytest.approx(EPSILON)
    # JS in nats never exceeds ln 2 < 1, so the upper clip is inactive for distributions
    p = _pixel([1.0, 0.0, 0.0])
    t = _pixel([0.0, 0.0, 1.0])
    assert js_divergence(p, t).item() == pytest.approx(math.log(2), abs=1e-5)


# --------------------------------------------------------------------------- the losses

def _case():
    """Two pixels, grid [-1, 0, 1]: P1 = [0.2, 0.5, 0.3], target 0.25; P2 = [0.6, 0.3, 0.1], target -0.5."""
    prob = torch.tensor([[0.2, 0.6], [0.5, 0.3], [0.3, 0.1]], dtype=torch.float64).view(1, 3, 1, 2)
    disp = (prob * GRID_1.double().view(1, -1, 1, 1)).sum(dim=1)  # [0.1, -0.5]
    target = torch.tensor([0.25, -0.5], dtype=torch.float64).view(1, 1, 2)
    return disp, prob, target


def _kl(a, b):
    return sum(max(x, EPSILON) * math.log(max(x, EPSILON) / max(y, EPSILON)) for x, y in zip(a, b, strict=True))


def _hand_values():
    p1, t1 = [0.2, 0.5, 0.3], [0.0, 0.75, 0.25]
    p2, t2 = [0.6, 0.3, 0.1], [0.5, 0.5, 0.0]  # -0.5: t = 0.5, l = 0 (0.5), r = 1 (0.5)
    m1 = [(a + b) / 2 for a, b in zip(p1, t1, strict=True)]
    m2 = [(a + b) / 2 for a, b in zip(p2, t2, strict=True)]
    js1 = 0.5 * (_kl(p1, m1) + _kl(t1, m1))
    js2 = 0.5 * (_kl(p2, m2) + _kl(t2, m2))
    err1, err2 = 0.15, 0.0  # |0.1 - 0.25|, |-0.5 - (-0.5)|
    return {
        "l1": (err1 + err2) / 2,
        "mse": (err1**2 + err2**2) / 2,
        "js": (js1 + js2) / 2,
        "kl": (_kl(t1, p1) + _kl(t2, p2)) / 2,
        "l1+js": (err1 + err2) / 2 + (js1 + js2) / 2,
        "l1+kl": (err1 + err2) / 2 + (_kl(t1, p1) + _kl(t2, p2)) / 2,
        "uafl": (js1**0.1 * err1 + js2**0.1 * err2) / 2,
    }


@pytest.mark.parametrize("name", list(LOSSES))
def test_every_loss_by_hand(name):
    disp, prob, target = _case()
    torch.testing.assert_close(disp.flatten(), torch.tensor([0.1, -0.5], dtype=torch.float64))
    value = make_loss(name)(disp, prob, target, GRID_1)
    assert value.dim() == 0
    assert value.item() == pytest.approx(_hand_values()[name], rel=1e-10)


def test_uafl_beta_zero_is_l1():
    gen = torch.Generator().manual_seed(1)
    prob = torch.softmax(torch.randn(2, 17, 4, 5, generator=gen), dim=1)
    disp = (prob * GRID_05.view(1, -1, 1, 1)).sum(dim=1)
    target = torch.rand(2, 4, 5, generator=gen) * 8 - 4
    assert torch.equal(uafl_loss(disp, prob, target, GRID_05, beta=0.0), make_loss("l1")(disp, prob, target, GRID_05))
    assert make_loss("uafl", beta=0.0)(disp, prob, target, GRID_05) == make_loss("l1")(disp, prob, target, GRID_05)


def test_uafl_gradient_flows_through_u():
    gen = torch.Generator().manual_seed(2)
    logits = torch.randn(1, 17, 2, 2, generator=gen, dtype=torch.float64, requires_grad=True)
    target = torch.rand(1, 2, 2, generator=gen, dtype=torch.float64) * 6 - 3
    grid = GRID_05.double()

    def loss_fn(lg, detach_u=False):
        prob = torch.softmax(lg, dim=1)
        disp = (prob * grid.view(1, -1, 1, 1)).sum(dim=1)
        if detach_u:
            u = uncertainty(prob, target, grid).detach()
            return (u.pow(0.1) * (disp - target).abs()).mean()
        return uafl_loss(disp, prob, target, grid, beta=0.1)

    # the full gradient matches finite differences (so it includes d U / d P) ...
    assert torch.autograd.gradcheck(loss_fn, (logits,), eps=1e-6, atol=1e-6)
    # ... and differs from the gradient with U held constant
    (g_full,) = torch.autograd.grad(loss_fn(logits), logits)
    (g_detached,) = torch.autograd.grad(loss_fn(logits, detach_u=True), logits)
    assert (g_full - g_detached).abs().max() > 1e-4


def test_make_loss_errors():
    with pytest.raises(SpecError, match="Unknown loss"):
        make_loss("huber")
    with pytest.raises(SpecError, match="no parameter"):
        make_loss("l1", beta=0.1)
    assert make_loss("UAFL", beta=0.5).__name__ == "uafl_loss(beta=0.5)"
