"""The eval fast path of SubFocal (methods/subfocal/fast.py) against independent references: the grid_sample
shifts of lfbench.data.shift, the layer-by-layer modules (eval with autograd on), explicit volume sums."""

from __future__ import annotations

import pytest
import torch
from lfbench_methods.subfocal import fast
from lfbench_methods.subfocal.inference import _tile_need, infer, plan_tiles
from lfbench_methods.subfocal.network import SubFocalNet

from lfbench.data.shift import angular_offsets, disparity_grid, shift_views

pytestmark = pytest.mark.usefixtures("one_torch_thread")  # small tensors: see conftest


def _net(seed: int = 0, **kw) -> SubFocalNet:
    torch.manual_seed(seed)
    net = SubFocalNet(**{"width": 4, **kw})
    g = torch.Generator().manual_seed(seed + 1)
    with torch.no_grad():  # non-trivial BN statistics and affine parameters, so that folding matters
        for name, t in list(net.named_buffers()) + list(net.named_parameters()):
            if name.endswith("running_mean") or (name.endswith("bn.bias")):
                t.copy_(torch.randn(t.shape, generator=g) * 0.1)
            elif name.endswith("running_var") or name.endswith("bn.weight"):
                t.copy_(torch.rand(t.shape, generator=g) + 0.5)
    return net.eval()


def _views(h: int, w: int, seed: int = 0) -> torch.Tensor:
    return torch.rand((1, 81, h, w), generator=torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("interval,slots", [(1.0, 1), (0.5, 2), (0.25, 4), (0.1, 10)])
def test_shift_plan_splits_every_shift_into_integer_and_shared_fraction(interval, slots):
    off = angular_offsets(9).double()
    d = disparity_grid(-4, 4, interval).double()
    plan = fast.shift_plan(-4.0, interval, d.numel(), angular_offsets(9))
    n = torch.arange(81)[None, :]
    fx, fy = plan.fx.double()[plan.slot, n], plan.fy.double()[plan.slot, n]
    # source = output - shift = output + o + f, f in [0, 1)
    assert torch.allclose(plan.ox + fx, -d[:, None] * off[None, :, 0], atol=1e-6)
    assert torch.allclose(plan.oy + fy, -d[:, None] * off[None, :, 1], atol=1e-6)
    assert float(fx.min()) >= 0 and float(fx.max()) < 1 and float(fy.max()) < 1
    # Fractions repeat across disparities: k * interval * du mod 1 takes 1 / interval values at most.
    assert plan.slots == slots and plan.pad == 17  # largest shift 4 px x 4 views + 1


@pytest.mark.parametrize("interval", [0.5, 0.1])
def test_gathered_volume_equals_grid_sample_shifts(interval):
    feats = torch.rand((1, 81, 4, 19, 23), generator=torch.Generator().manual_seed(1))
    grid = disparity_grid(-4, 4, interval)
    ref = shift_views(feats, angular_offsets(9), grid, "bilinear")  # (1, D, N, C, H, W)
    plan = fast.shift_plan(-4.0, interval, grid.numel(), angular_offsets(9))
    gather = fast.VolumeGather(plan, fast.pad_features(feats, plan.pad), 2, 17, 3, 21)
    out = torch.empty((1, grid.numel(), 15, 18, 324))
    gather.fill(out[:, :5], 0, 5)
    gather.fill(out[:, 5:], 5, grid.numel())
    expected = ref[..., 2:17, 3:21].permute(0, 1, 4, 5, 2, 3).reshape(out.shape)
    # grid_sample's normalised coordinates round positions by ~1e-7 x size; the gather shifts exactly.
    assert (out - expected).abs().max().item() < 2e-5
    # bf16: the same values rounded once.
    g16 = fast.VolumeGather(plan, fast.pad_features(feats, plan.pad), 2, 17, 3, 21, torch.bfloat16)
    out16 = torch.empty(out.shape, dtype=torch.bfloat16)
    g16.fill(out16, 0, grid.numel())
    assert (out16.float() - out).abs().max().item() <= 2 ** -8


def test_attention_sum_is_the_sum_of_the_volume():
    feats = torch.rand((1, 81, 4, 21, 17), generator=torch.Generator().manual_seed(2))
    grid = disparity_grid(-4, 4, 0.25)
    vol = shift_views(feats.double(), angular_offsets(9), grid, "bilinear")  # (1, D, N, C, H, W)
    expected = vol.sum(dim=(1, 4, 5)).reshape(1, 324)
    plan = fast.shift_plan(-4.0, 0.25, grid.numel(), angular_offsets(9))
    got = fast.attention_sum(plan, fast.pad_features(feats, plan.pad), 21, 17, row_chunk=7)
    assert got.dtype == torch.float64
    assert ((got - expected).abs() / expected.abs()).max().item() < 1e-5


def test_folded_extractor_and_aggregation_equal_the_modules():
    net = _net(width=5)
    x = torch.rand((3, 1, 20, 26), generator=torch.Generator().manual_seed(3))
    with torch.no_grad():
        ref = net.extractor(x)
        got = fast.FastExtractor(net.extractor)(x)
    assert got.shape == ref.shape and got.is_contiguous(memory_format=torch.channels_last)
    assert (got - ref).abs().max().item() < 1e-4 * max(1.0, ref.abs().max().item())
    vol = torch.rand((1, 324, 9, 11, 13), generator=torch.Generator().manual_seed(4))
    att = torch.rand((1, 324), generator=torch.Generator().manual_seed(5))
    with torch.no_grad():
        expected = net.aggregation(vol * att[:, :, None, None, None])

        class Source:  # slabs straight from the volume
            released = False

            def fill(self, out, d0, d1):
                out.copy_(vol[:, :, d0:d1].permute(0, 2, 3, 4, 1))

            def release(self):
                self.released = True

        src = Source()
        cost = fast.FastAggregation(net.aggregation)(src, 1, 9, 11, 13, att, (2, 9, 1, 13), slab=2)
    assert src.released
    assert (cost - expected[:, :, 2:9, 1:13]).abs().max().item() < 1e-4 * max(1.0, expected.abs().max().item())


@pytest.mark.parametrize("kw", [{}, {"interval": 0.1, "d_min": -1, "d_max": 1}, {"attention": False},
                                {"interpolation": "nearest"}, {"interpolation": "phase", "interval": 1}])
def test_fast_eval_forward_equals_the_layer_by_layer_forward(kw):
    net = _net(**kw)
    views = _views(22, 19)
    with torch.no_grad():
        assert net.uses_fast_path()
        disp, prob = net(views)
    with torch.enable_grad():  # eval mode with autograd on: the modules, layer by layer
        assert not net.uses_fast_path()
        ref_disp, ref_prob = net(views)
    assert (disp - ref_disp).abs().max().item() < 1e-4
    assert (prob - ref_prob).abs().max().item() < 1e-4
    net.fast_inference = False
    with torch.no_grad():
        assert not net.uses_fast_path() and torch.equal(net(views)[0], ref_disp.detach())


def test_halo_of_eight_is_exact_and_seven_is_not():
    net = _net()
    views = _views(30, 30, seed=5)
    with torch.no_grad():
        disp, _ = net(views)
    assert (infer(net, views, tile=10, halo=8).disparity - disp).abs().max().item() < 5e-5  # float rounding
    assert (infer(net, views, tile=10, halo=7).disparity - disp).abs().max().item() > 1e-3


def test_plain_ops_without_onednn_fusion_give_the_same_result(monkeypatch):
    net = _net()
    views = _views(18, 20, seed=6)
    fused = infer(net, views, tile=9)
    monkeypatch.setattr(fast, "fused_ops_work", lambda: False)
    plain = infer(net, views, tile=9)
    assert (fused.disparity - plain.disparity).abs().max().item() < 1e-5


def test_planner_takes_the_cheapest_tiling_that_fits(monkeypatch):
    from lfbench_methods.subfocal import inference

    monkeypatch.setattr(inference, "cpu_has_amx_bf16", lambda: False)  # no width limit (see the next test)
    paper = SubFocalNet()
    assert plan_tiles(paper, 64, 64, max_memory_gb=100) == (64, 64)  # everything fits: one piece
    plan = fast.net_shift_plan(paper)
    for precision in ("fp32", "bf16"):
        th, tw = plan_tiles(paper, 512, 512, max_memory_gb=4, precision=precision)
        rows, cols = min(th + 16, 512), min(tw + 16, 512)
        assert _tile_need(paper, rows, cols, precision, plan) < 4e9
        assert _tile_need(paper, 512, 512, precision, plan) > _tile_need(paper, rows, cols, precision, plan)
    # bf16 halves the activations: its tiles are at least as large as fp32's.
    assert (lambda a, b: a[0] * a[1] >= b[0] * b[1])(plan_tiles(paper, 512, 512, precision="bf16"),
                                                      plan_tiles(paper, 512, 512, precision="fp32"))


@pytest.mark.parametrize("amx", [False, True])
def test_bf16_tiles_on_an_amx_cpu_stay_narrower_than_onednn_s_slow_path(monkeypatch, amx):
    from lfbench_methods.subfocal import inference

    monkeypatch.setattr(inference, "cpu_has_amx_bf16", lambda: amx)
    paper = SubFocalNet()

    def widest(size: int, precision: str, device=None) -> int:
        """The widest region (core + halo, px) a 3D convolution runs on under the plan."""
        _, tw = plan_tiles(paper, size, size, max_memory_gb=4, precision=precision, device=device)
        return max(c1 - c0 for *_, c0, c1 in inference._spans(size, tw, inference.EXACT_HALO))

    # 256x256: one 256 px wide piece, unless bf16 on AMX, where oneDNN's AMX kernels are slow from 256 px.
    assert widest(256, "bf16") == (128 + 8 if amx else 256)
    assert widest(512, "bf16") == (171 + 16 if amx else 256 + 8)  # 3 strips instead of 2
    assert widest(256, "fp32") == 256 and widest(512, "fp32") == 171 + 16  # fp32 never runs on AMX
    assert inference.conv_width_limit("bf16", torch.device("cuda")) is None  # a GPU: no limit
    assert inference.conv_width_limit("bf16") == (inference.AMX_MAX_CONV_WIDTH if amx else None)


def test_inference_keeps_to_the_width_limit_and_stays_exact(monkeypatch):
    from lfbench_methods.subfocal import inference

    net = _net()
    views = _views(20, 64, seed=7)
    whole = infer(net, views, tile=64)
    monkeypatch.setattr(inference, "conv_width_limit", lambda precision="fp32", device=None: 40)
    timings: dict = {}
    limited = infer(net, views, timings=timings)
    spans = inference._spans(64, timings["tile"][1], inference.EXACT_HALO)
    assert max(c1 - c0 for *_, c0, c1 in spans) <= 40 and timings["tiles"] == len(spans) == 2  # 2 x (32 + 8) px
    assert (limited.disparity - whole.disparity).abs().max().item() < 1e-5
