"""The SubFocal network: parameter counts, shapes, Keras pooling/attention/BN conventions, sub-pixel shifts."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from lfbench_methods.subfocal.network import (
    SubFocalNet,
    ViewBatchNorm2d,
    attention_index,
    count_trainable,
    keras_avg_pool_same,
)
from torch import nn

from lfbench.data.shift import angular_offsets, disparity_grid

EXTRACTOR = 34_164  # trainable parameters of the shared 2D feature extractor
ATTENTION = 324 * 170 + 170 + 170 * 15 + 15  # two 1x1x1 Conv3D with bias


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # small tensors: see conftest


def aggregation_params(width: int, cin: int = 324) -> int:
    """3x3x3 kernels: cin->w, six w->w, w->1 (no bias); seven BN layers with gamma and beta."""
    return 27 * (cin * width + 6 * width * width + width) + 7 * 2 * width


def test_paper_configuration_has_exactly_the_published_trainable_parameters():
    net = SubFocalNet()
    assert count_trainable(net) == 5_055_329
    assert count_trainable(net.extractor) == EXTRACTOR
    # 2,804 BN running statistics (mean and variance), as in the Keras model's 5,058,133 total.
    stats = sum(m.running_mean.numel() + m.running_var.numel() for m in net.modules()
                if isinstance(m, nn.modules.batchnorm._BatchNorm))
    assert stats == 2_804


@pytest.mark.parametrize("width,attention,interval", [(150, False, 0.5), (16, True, 0.5), (8, False, 0.1),
                                                      (150, True, 1.0), (150, True, 0.1)])
def test_parameter_count_follows_width_and_attention_not_interval(width, attention, interval):
    net = SubFocalNet(width=width, attention=attention, interval=interval)
    expected = EXTRACTOR + aggregation_params(width) + (ATTENTION if attention else 0)
    assert count_trainable(net) == expected
    assert net.disparities.numel() == round(8 / interval) + 1


@pytest.mark.parametrize("interval,d", [(1.0, 9), (0.5, 17), (0.25, 33), (0.1, 81)])
def test_forward_shapes_dtypes_and_distribution(interval, d):
    torch.manual_seed(0)
    net = SubFocalNet(interval=interval, width=2).eval()
    views = torch.rand(1, 81, 12, 10)
    with torch.inference_mode():
        disp, prob = net(views)
    assert disp.shape == (1, 12, 10) and prob.shape == (1, d, 12, 10)
    assert disp.dtype == torch.float32 and prob.dtype == torch.float32
    assert torch.allclose(prob.sum(1), torch.ones(1, 12, 10), atol=1e-5)
    grid = disparity_grid(-4, 4, interval)
    assert torch.allclose(net.disparities, grid)
    assert torch.allclose(disp, (prob * grid[None, :, None, None]).sum(1), atol=1e-5)
    assert float(disp.min()) >= -4 and float(disp.max()) <= 4


def test_training_forward_backward_reaches_every_parameter():
    torch.manual_seed(0)
    net = SubFocalNet(width=3, interval=1.0).train()
    disp, prob = net(torch.rand(2, 81, 8, 8))
    assert disp.shape == (2, 8, 8) and prob.shape == (2, 9, 8, 8)
    disp.abs().mean().backward()
    missing = [n for n, p in net.named_parameters() if p.grad is None]
    assert not missing


def test_config_round_trip():
    net = SubFocalNet(d_min=-2, d_max=2, interval=0.25, interpolation="phase", width=5, attention=False)
    cfg = net.config()
    assert cfg == {"d_min": -2.0, "d_max": 2.0, "interval": 0.25, "interpolation": "phase", "width": 5,
                   "attention": False, "angular": 9}
    twin = SubFocalNet(**cfg)
    twin.load_state_dict(net.state_dict())
    with pytest.raises(ValueError):
        SubFocalNet(interpolation="cubic")


def test_keras_glorot_uniform_init_and_bn_conventions():
    torch.manual_seed(0)
    net = SubFocalNet(width=150)
    w = net.aggregation.dres0b.conv.weight.detach()  # (150, 150, 3, 3, 3)
    limit = math.sqrt(6 / (150 * 27 + 150 * 27))
    assert float(w.abs().max()) <= limit and float(w.abs().max()) > 0.95 * limit
    assert abs(float(w.std()) - limit / math.sqrt(3)) < 0.02 * limit
    assert torch.count_nonzero(net.attention.fc1.bias) == 0
    for m in net.modules():
        if isinstance(m, nn.modules.batchnorm._BatchNorm):
            assert m.eps == 1e-3 and m.momentum == pytest.approx(0.01)


def test_keras_same_average_pooling_excludes_padding():
    # TensorFlow's 'same' average pooling (the authors' Keras model): p = 4 on 0..9 gives 1, 4.5, 8
    # (pad 2 split 1 before, 1 after).
    x = torch.arange(10, dtype=torch.float32)[None, None, None, :].expand(1, 1, 4, 10)
    y = keras_avg_pool_same(x, 4)
    assert y.shape == (1, 1, 1, 3)
    assert torch.allclose(y[0, 0, 0], torch.tensor([1.0, 4.5, 8.0]))
    # Odd total padding puts the extra cell after: n = 5, p = 4 -> pad 3 = 1 before + 2 after.
    x = torch.arange(5, dtype=torch.float32)[None, None, None, :].expand(1, 1, 4, 5)
    assert torch.allclose(keras_avg_pool_same(x, 4)[0, 0, 0], torch.tensor([1.0, 3.5]))
    # Multiples of p: plain average pooling.
    x = torch.rand(2, 3, 16, 8)
    assert torch.allclose(keras_avg_pool_same(x, 8), x.reshape(2, 3, 2, 8, 1, 8).mean(dim=(3, 5)))


def test_attention_index_is_symmetric_5x5_reflected_to_9x9():
    a = attention_index(9).reshape(9, 9)
    assert a[0, 0] == 0 and a[0, 4] == 4 and a[1, 1] == 5 and a[1, 4] == 8 and a[2, 2] == 9
    assert a[3, 3] == 12 and a[3, 4] == 13 and a[4, 4] == 14 and a[4, 0] == 4
    assert torch.equal(a, a.T)
    assert torch.equal(a, a.flip(0)) and torch.equal(a, a.flip(1))  # A9[v, u] = A5[min(v, 8-v), ...]
    assert sorted(set(a.flatten().tolist())) == list(range(15))
    net = SubFocalNet(width=2)
    assert torch.equal(net.attention.index, a.flatten().repeat_interleave(4))  # channel 4*view + c


def test_view_batchnorm_matches_one_keras_call_per_view():
    torch.manual_seed(0)
    views, batch = 3, 4
    bn = ViewBatchNorm2d(2, eps=1e-3, momentum=0.01)
    with torch.no_grad():
        bn.weight.copy_(torch.tensor([1.5, 0.5]))
        bn.bias.copy_(torch.tensor([0.1, -0.2]))
        bn.running_mean.copy_(torch.tensor([0.3, -0.1]))
        bn.running_var.copy_(torch.tensor([2.0, 0.5]))
    ref = nn.BatchNorm2d(2, eps=1e-3, momentum=0.01)
    ref.load_state_dict(bn.state_dict())
    x = torch.randn(views * batch, 2, 5, 6) * torch.tensor([1.0, 3.0])[None, :, None, None] + 2.0
    out = bn.train()(x, groups=views)
    expected = torch.cat([ref.train()(chunk) for chunk in x.split(batch)])  # sequential calls, view 0 first
    assert torch.allclose(out, expected, atol=1e-5)
    assert torch.allclose(bn.running_mean, ref.running_mean, atol=1e-6)
    assert torch.allclose(bn.running_var, ref.running_var, atol=1e-6)
    # Eval mode ignores groups.
    assert torch.allclose(bn.eval()(x, groups=views), ref.eval()(x), atol=1e-6)


def _plane_views(d0: float, texture, size: int = 40) -> torch.Tensor:
    """(1, 81, 1, size, size) views of a fronto-parallel plane at disparity d0: view (u, v) at (y, x)
    shows the centre view at (y + d0 (v - 4), x + d0 (u - 4)); ``texture(y, x)`` float64 analytic."""
    off = angular_offsets(9).double()
    y = torch.arange(size, dtype=torch.float64)[None, :, None] + d0 * off[:, 1, None, None]
    x = torch.arange(size, dtype=torch.float64)[None, None, :] + d0 * off[:, 0, None, None]
    return texture(y, x).float()[None, :, None]


# A smooth texture with analytic derivative bounds (a = 2pi/17, b = 2pi/23, c = 2pi/29): bilinear
# interpolation errs by at most (max|f_xx| + max|f_yy|) / 8 on a unit grid, nearest by at most
# 0.5 (max|f_x| + max|f_y|).
_A, _B, _C = 2 * math.pi / 17, 2 * math.pi / 23, 2 * math.pi / 29
_BOUNDS = {"bilinear": ((_A**2 + 0.5 * _C**2) + (_B**2 + 0.5 * _C**2)) / 8,
           "nearest": 0.5 * ((_A + 0.5 * _C) + (_B + 0.5 * _C))}


def _smooth(y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    return torch.cos(_A * x + 0.3) * torch.cos(_B * y) + 0.5 * torch.sin(_C * (x + y))


def _bandlimited_bump(y: torch.Tensor, x: torch.Tensor, centre: float = 31.5, sigma: float = 6.0) -> torch.Tensor:
    """High-frequency texture under a Gaussian window: ~0 at the borders and (numerically) band-limited,
    so a Fourier phase shift on a zero-padded canvas is exact."""
    window = torch.exp(-((x - centre) ** 2 + (y - centre) ** 2) / (2 * sigma**2))
    return torch.cos(2 * math.pi * x / 7.0 + 0.3) * torch.cos(2 * math.pi * y / 5.0) * window


@pytest.mark.parametrize("mode", ["bilinear", "nearest"])
def test_cost_volume_undoes_a_known_subpixel_shift(mode):
    # True disparity 0.75 px: view offsets of 0.75, 1.5, 2.25 and 3 px. At the candidate 0.75 every
    # view must be realigned with the centre view (within the interpolation's analytic error bound);
    # the neighbouring candidates must not.
    d0, size, margin = 0.75, 40, 8
    net = SubFocalNet(d_min=-1, d_max=1, interval=0.25, interpolation=mode, width=2)
    feats = _plane_views(d0, _smooth, size)
    vol = net.cost_volume(feats)  # (1, 81, D, H, W)
    err = (vol[0] - feats[0, 40, 0]).abs()[..., margin:size - margin, margin:size - margin]  # (81, D, h, w)
    k = int(torch.argmin((net.disparities - d0).abs()))
    assert err[:, k].max().item() < _BOUNDS[mode]
    for wrong in (k - 1, k + 1):
        assert err[:, wrong].mean().item() > 2 * err[:, k].mean().item()
    # Integer shifts are exact.
    k1 = int(torch.argmin((net.disparities - 1.0).abs()))
    ints = _plane_views(1.0, _smooth, size)
    exact = (net.cost_volume(ints)[0, :, k1] - ints[0, 40, 0]).abs()[:, margin:size - margin, margin:size - margin]
    assert exact.max().item() < 1e-5


def test_phase_shift_is_exact_for_a_bandlimited_texture():
    d0, size = 0.75, 64
    feats = _plane_views(d0, _bandlimited_bump, size)
    k = 7  # candidate 0.75 in [-1, 1] step 0.25
    phase = SubFocalNet(d_min=-1, d_max=1, interval=0.25, interpolation="phase", width=2).cost_volume(feats)
    assert (phase[0, :, k] - feats[0, 40, 0]).abs().max().item() < 1e-4  # the whole image, every view
    assert (phase[0, :, k - 1] - feats[0, 40, 0]).abs().mean().item() > 0.01
    # bilinear cannot follow a 5 px period: the phase shift is the better interpolator here.
    bilinear = SubFocalNet(d_min=-1, d_max=1, interval=0.25, width=2).cost_volume(feats)
    assert (bilinear[0, :, k] - feats[0, 40, 0]).abs().max().item() > 0.1


def test_bilinear_half_pixel_shift_is_the_mean_of_neighbours():
    # Hand case: shifting by 0.5 px with bilinear interpolation averages two neighbouring pixels.
    net = SubFocalNet(d_min=-0.5, d_max=0.5, interval=0.5, width=1)
    img = torch.tensor(np.random.default_rng(0).random((6, 7)), dtype=torch.float32)
    feats = img[None, None, None].expand(1, 81, 4, 6, 7).contiguous()
    vol = net.cost_volume(feats)  # channel 4 * view + c
    view = 41  # u - uc = 1, v - vc = 0: at d = 0.5 out(y, x) = F(y, x - 0.5)
    out = vol[0, 4 * view, 2]
    expected = torch.zeros_like(img)
    expected[:, 1:] = 0.5 * (img[:, 1:] + img[:, :-1])
    expected[:, 0] = 0.5 * img[:, 0]  # the left neighbour is outside the image: zero fill
    assert torch.allclose(out, expected, atol=1e-6)
