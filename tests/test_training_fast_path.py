"""The fast training path of SubFocal (fused per-view BatchNorm, grouped stem convolution, gathered
bilinear cost volume, matrix-product weight gradients) against the original layer-by-layer ops kept as the
``reference`` path: the same outputs, gradients, running statistics and a few optimizer steps, up to float32
rounding."""

from __future__ import annotations

import copy

import pytest
import torch
from lfbench_methods.subfocal.network import SubFocalNet, ViewBatchNorm2d
from lfbench_methods.subfocal.volume import GatheredVolume
from torch import nn

from lfbench.data.shift import shift_views
from lfbench.method.trainable import to_channels_last

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _bn_pair(channels: int) -> tuple[ViewBatchNorm2d, ViewBatchNorm2d]:
    fast = ViewBatchNorm2d(channels, eps=1e-3, momentum=0.01)
    with torch.no_grad():
        fast.weight.copy_(torch.linspace(0.5, 1.5, channels))
        fast.bias.copy_(torch.linspace(-0.2, 0.3, channels))
        fast.running_mean.copy_(torch.linspace(-1, 1, channels))
        fast.running_var.copy_(torch.linspace(0.5, 2, channels))
    ref = copy.deepcopy(fast)
    ref.reference = True
    return fast.train(), ref.train()


@pytest.mark.parametrize("channels_last", [True, False])
@pytest.mark.parametrize("channels,batch,size", [(4, 3, (8, 6)), (16, 2, (5, 7))])
def test_fused_view_batchnorm_matches_the_reference(channels_last, channels, batch, size):
    torch.manual_seed(0)
    groups = 5
    fast, ref = _bn_pair(channels)
    # Channel means far from 0 relative to their spread: the case where one-pass variances lose digits.
    x = torch.randn(groups * batch, channels, *size) * torch.linspace(0.1, 3, channels)[None, :, None, None] + 4.0
    if channels_last:
        x = x.contiguous(memory_format=torch.channels_last)
    xa, xb = x.clone().requires_grad_(), x.clone().requires_grad_()
    ya, yb = fast(xa, groups), ref(xb, groups)
    assert ya.shape == yb.shape == x.shape
    torch.testing.assert_close(ya, yb, rtol=0, atol=2e-5)
    g = torch.randn_like(ya)
    da = torch.autograd.grad(ya, (xa, fast.weight, fast.bias), g)
    db = torch.autograd.grad(yb, (xb, ref.weight, ref.bias), g)
    for a, b in zip(da, db, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4 * float(b.abs().max()))
    torch.testing.assert_close(fast.running_mean, ref.running_mean, rtol=1e-6, atol=1e-6)
    torch.testing.assert_close(fast.running_var, ref.running_var, rtol=1e-5, atol=1e-6)
    assert int(fast.num_batches_tracked) == int(ref.num_batches_tracked) == groups


def test_fused_view_batchnorm_normalises_each_view_by_hand():
    # Two views of one sample, one channel: view 0 holds 0, 2 (mean 1, var 1), view 1 holds 10, 14 (mean 12,
    # var 4); gamma 2, beta 1, eps 0 -> view 0: -1, 3; view 1: -1, 3.
    bn = ViewBatchNorm2d(1, eps=0.0, momentum=0.5).train()
    with torch.no_grad():
        bn.weight.fill_(2.0)
        bn.bias.fill_(1.0)
    x = torch.tensor([0.0, 2.0, 10.0, 14.0]).reshape(2, 1, 1, 2)
    y = bn(x, groups=2)
    assert y.flatten().tolist() == pytest.approx([-1.0, 3.0, -1.0, 3.0], abs=1e-6)
    # Running mean: 0 -> 0.5 * 0 + 0.5 * 1 = 0.5 -> 0.5 * 0.5 + 0.5 * 12 = 6.25; running var (unbiased:
    # 2 and 8): 1 -> 1.5 -> 4.75.
    assert float(bn.running_mean) == pytest.approx(6.25)
    assert float(bn.running_var) == pytest.approx(4.75)


@pytest.mark.parametrize("interval", [1.0, 0.5, 0.25, 0.1])
def test_gathered_volume_matches_grid_sample_values_means_and_gradients(interval):
    torch.manual_seed(1)
    net = SubFocalNet(width=2, interval=interval)
    feats = torch.randn(2, 81, 4, 9, 11)
    fa, fb = feats.clone().requires_grad_(), feats.clone().requires_grad_()
    weights = torch.rand(2, 324) + 0.5
    wa, wb = weights.clone().requires_grad_(), weights.clone().requires_grad_()
    gathered = GatheredVolume(net._shift_plan(), fa)
    vol_ref = shift_views(fb, net.offsets, net.disparities, "bilinear")  # (B, D, N, C, H, W)
    vol_ref = vol_ref.reshape(2, net.disparities.numel(), 324, 9, 11).transpose(1, 2)
    torch.testing.assert_close(gathered.channel_mean(), vol_ref.mean(dim=(2, 3, 4)), rtol=0, atol=1e-6)
    vol = gathered.volume(wa)
    assert vol.shape == vol_ref.shape
    assert vol.is_contiguous(memory_format=torch.channels_last_3d)
    expected = vol_ref * wb[:, :, None, None, None]
    torch.testing.assert_close(vol, expected, rtol=0, atol=2e-5)
    g = torch.randn_like(expected)
    ga, gwa = torch.autograd.grad((vol * g).sum() + gathered.channel_mean().sum(), (fa, wa))
    gb, gwb = torch.autograd.grad((expected * g).sum() + vol_ref.mean(dim=(2, 3, 4)).sum(), (fb, wb))
    torch.testing.assert_close(ga, gb, rtol=0, atol=1e-4)
    torch.testing.assert_close(gwa, gwb, rtol=0, atol=1e-4 * float(gwb.abs().max()))


def test_two_grids_of_the_same_size_do_not_share_a_gather_index():
    # Same number of disparities and the same patch shape, other offsets (an ablation over d_min in one
    # process): the second volume and its channel means must follow its own grid, not reuse the first
    # one's cached index and mean weights; a new patch size of the same grid must not reuse them either.
    torch.manual_seed(2)
    nets = {d_min: SubFocalNet(width=2, interval=0.5, d_min=d_min, d_max=d_min + 8) for d_min in (-4.0, -3.0)}
    for d_min, h, w in ((-4.0, 9, 11), (-3.0, 9, 11), (-3.0, 7, 11)):
        feats = torch.randn(1, 81, 4, h, w)
        net = nets[d_min]
        gathered = GatheredVolume(net._shift_plan(), feats)
        ref = shift_views(feats, net.offsets, net.disparities, "bilinear")
        ref = ref.reshape(1, net.disparities.numel(), 324, h, w).transpose(1, 2)
        torch.testing.assert_close(gathered.volume(), ref, rtol=0, atol=2e-5)
        torch.testing.assert_close(gathered.channel_mean(), ref.mean(dim=(2, 3, 4)), rtol=0, atol=1e-6)


def test_an_integer_shift_is_exact_in_the_gathered_volume():
    # At interval 1 every shift is an integer number of pixels: the volume is a pure copy of the features
    # (zeros outside). out(y, x) = F(y - d dv, x - d du): view (u, v) = (8, 4) at d = 1 moves its map 4 px
    # to the right.
    net = SubFocalNet(width=2, interval=1.0)
    feats = torch.arange(81 * 4 * 6 * 7, dtype=torch.float32).reshape(1, 81, 4, 6, 7)
    vol = GatheredVolume(net._shift_plan(), feats).volume()  # (1, 324, 9, 6, 7)
    d = int((net.disparities == 1.0).nonzero())
    view = 4 * 9 + 8
    got = vol[0, 4 * view:4 * view + 4, d]
    assert torch.equal(got[..., 4:], feats[0, view, :, :, :3])
    assert torch.equal(got[..., :4], torch.zeros(4, 6, 4))


def _pair(width: int = 4, interval: float = 0.5, attention: bool = True,
          dtype: torch.dtype = torch.float32, weight_grad: str = "auto") -> tuple[SubFocalNet, SubFocalNet]:
    torch.manual_seed(3)
    fast = to_channels_last(SubFocalNet(width=width, interval=interval, attention=attention)).to(dtype).train()
    fast.set_training_path("fast", weight_grad=weight_grad)
    ref = copy.deepcopy(fast).set_training_path("reference")
    return fast, ref


def _batches(count: int, dtype: torch.dtype) -> list[tuple[torch.Tensor, torch.Tensor]]:
    g = torch.Generator().manual_seed(1)
    return [(torch.rand((2, 81, 12, 12), generator=g).to(dtype),
             (torch.rand((2, 12, 12), generator=g) * 8 - 4).to(dtype)) for _ in range(count)]


# In float64 the two paths are the same arithmetic up to rounding. (In float32 a rounding difference flips the
# odd ReLU whose input is within 1e-7 of 0, which moves a gradient element by ~1e-3 of its tensor's largest:
# chaotic, not systematic. float64 leaves ~5e-6: the reference's sampling positions and the softmax stay
# float32.)
@pytest.mark.parametrize("attention,weight_grad", [(True, "auto"), (False, "auto"), (True, "gemm")])
def test_training_step_gradients_match_the_reference_path(attention, weight_grad):
    # weight_grad "gemm": the matrix-product weight gradients (weight_grad.py) on every layer they apply to,
    # whatever the CPU ("auto" takes them only where ATen runs its AVX2 kernels)
    fast, ref = _pair(attention=attention, dtype=torch.float64, weight_grad=weight_grad)
    views, target = _batches(1, torch.float64)[0]
    losses = []
    for net in (fast, ref):
        disp, prob = net(views)
        loss = nn.functional.l1_loss(disp, target) + 0.1 * prob.square().mean()
        loss.backward()
        losses.append(float(loss.detach()))
    assert losses[0] == pytest.approx(losses[1], rel=1e-7)
    for (name, pa), pb in zip(fast.named_parameters(), ref.parameters(), strict=True):
        scale = float(pb.grad.abs().max())
        torch.testing.assert_close(pa.grad, pb.grad, rtol=0, atol=3e-5 * scale + 1e-12, msg=name)
    for (name, ba), bb in zip(fast.named_buffers(), ref.buffers(), strict=True):  # running statistics
        torch.testing.assert_close(ba, bb, rtol=1e-6, atol=1e-9, msg=name)


def _curve(net: SubFocalNet, batches, optimizer: str = "adam") -> list[float]:
    if optimizer == "adam":
        opt = torch.optim.Adam(net.parameters(), lr=1e-3, eps=1e-7)
    else:
        opt = torch.optim.SGD(net.parameters(), lr=0.05)
    curve = []
    for views, target in batches:
        opt.zero_grad(set_to_none=True)
        loss = nn.functional.l1_loss(net(views)[0], target)
        loss.backward()
        opt.step()
        curve.append(float(loss.detach()))
    return curve


@pytest.mark.slow
def test_a_few_sgd_steps_follow_the_reference_in_float64():
    # SGD is linear in the gradients, so the paths' agreement carries over to the weights.
    fast, ref = _pair(dtype=torch.float64)
    start = [p.detach().clone() for p in ref.parameters()]
    batches = _batches(3, torch.float64)
    a, b = _curve(fast, batches, "sgd"), _curve(ref, batches, "sgd")
    assert a == pytest.approx(b, rel=1e-6)
    assert a[-1] != pytest.approx(a[0], rel=1e-3)  # the weights did move
    for (name, pa), pb, p0 in zip(fast.named_parameters(), ref.parameters(), start, strict=True):
        moved = pb.detach() - p0
        torch.testing.assert_close(pa.detach() - p0, moved, rtol=0, atol=3e-5 * float(moved.abs().max()), msg=name)


@pytest.mark.parametrize("weight_grad", ["auto", "gemm"])
def test_the_float32_loss_curve_stays_within_rounding_of_the_reference(weight_grad):
    # Adam divides by sqrt(v) + 1e-7: parameters with near-zero gradients take unit-size steps whose sign is
    # rounding noise, so float32 curves separate slowly (~1e-4 relative after 4 steps) on either path.
    fast, ref = _pair(weight_grad=weight_grad)
    batches = _batches(4, torch.float32)
    a, b = _curve(fast, batches), _curve(ref, batches)
    assert a[0] == pytest.approx(b[0], rel=1e-6)  # before any update
    assert a == pytest.approx(b, rel=2e-3)


def test_training_path_is_validated_and_eval_mode_is_untouched():
    fast, ref = _pair(width=2)
    with pytest.raises(ValueError, match="Unknown training path 'slow'. Available: fast, reference"):
        fast.set_training_path("slow")
    views = torch.rand((1, 81, 12, 12))
    fast.eval()
    ref.eval()
    with torch.no_grad():
        assert torch.equal(fast(views)[0], ref(views)[0])


def test_retain_freed_memory_applies_on_glibc():
    import platform

    from lfbench.utils.malloc import retain_freed_memory

    applied = retain_freed_memory()
    assert retain_freed_memory() is applied  # idempotent (cached)
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert applied is True


def test_the_fast_path_trains_under_bf16_autocast():
    from lfbench.utils.hardware import bf16_missing

    missing = bf16_missing(torch.device("cpu"))
    if missing is not None:
        pytest.skip(f"bf16 convolutions: this CPU lacks {missing}")
    fast, _ = _pair()
    views, target = _batches(1, torch.float32)[0]
    ref = nn.functional.l1_loss(fast(views)[0], target)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        disp, prob = fast(views)
    assert disp.dtype == torch.float32 and prob.dtype == torch.float32  # the softmax regression stays fp32
    loss = nn.functional.l1_loss(disp, target)
    loss.backward()
    assert float(loss.detach()) == pytest.approx(float(ref.detach()), rel=0.05)  # bf16: ~3 significant digits
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in fast.parameters())
    assert all(p.grad.dtype == torch.float32 for p in fast.parameters())
