"""The matrix-product weight gradient of methods/subfocal/weight_grad.py against PyTorch's own convolution
backward (an independent implementation) and a hand-computed case, and the layers it is used on."""

from __future__ import annotations

import pytest
import torch
from lfbench_methods.subfocal import weight_grad as wg
from lfbench_methods.subfocal.network import SubFocalNet
from torch import nn

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _aten_weight_grad(x: torch.Tensor, grad: torch.Tensor, weight: torch.Tensor, dilation: int) -> torch.Tensor:
    nd = x.dim() - 2
    pad = dilation * (weight.shape[-1] // 2)
    return torch.ops.aten.convolution_backward(grad, x, weight, None, [1] * nd, [pad] * nd, [dilation] * nd, False,
                                               [0] * nd, 1, [False, True, False])[1]


@pytest.mark.parametrize("size,kernel,dilation", [
    ((2, 5, 7, 6), 3, 1), ((3, 4, 9, 5), 3, 2), ((1, 3, 6, 6), 1, 1), ((2, 6, 8, 7), 5, 1),
    ((2, 7, 4, 6, 5), 3, 1), ((1, 3, 5, 9, 6), 3, 2), ((2, 70, 3, 4, 4), 3, 1)])
@pytest.mark.parametrize("channels_last", [True, False])
@pytest.mark.parametrize("rows_per_chunk", [7, 4096])
def test_gemm_weight_grad_matches_torch(size, kernel, dilation, channels_last, rows_per_chunk):
    g = torch.Generator().manual_seed(sum(size) + kernel)
    nd = len(size) - 2
    x = torch.randn(size, generator=g, dtype=torch.float64)
    grad = torch.randn((size[0], 3, *size[2:]), generator=g, dtype=torch.float64)
    if channels_last:
        fmt = torch.channels_last_3d if nd == 3 else torch.channels_last
        x, grad = x.contiguous(memory_format=fmt), grad.contiguous(memory_format=fmt)
    weight = torch.zeros((3, size[1], *[kernel] * nd), dtype=torch.float64)
    got = wg.gemm_weight_grad(x, grad, kernel, dilation, rows_per_chunk=rows_per_chunk)
    torch.testing.assert_close(got, _aten_weight_grad(x, grad, weight, dilation), rtol=1e-12, atol=1e-12)


def test_gemm_weight_grad_by_hand():
    # One output position with gradient 1: the weight gradient is the input window around it, zero where
    # the window leaves the image (the 'same' padding), dilated by 2.
    x = torch.arange(1.0, 26.0, dtype=torch.float64).reshape(1, 1, 5, 5)
    grad = torch.zeros((1, 1, 5, 5), dtype=torch.float64)
    grad[0, 0, 1, 3] = 1.0
    got = wg.gemm_weight_grad(x, grad, 3, dilation=2)[0, 0]
    # taps at rows 1 - 2, 1, 1 + 2 = (-1, 1, 3) and columns 3 - 2, 3, 3 + 2 = (1, 3, 5)
    expected = torch.tensor([[0.0, 0.0, 0.0], [7.0, 9.0, 0.0], [17.0, 19.0, 0.0]], dtype=torch.float64)
    torch.testing.assert_close(got, expected, rtol=0, atol=0)


def test_the_convolution_keeps_its_values_and_input_gradient():
    torch.manual_seed(0)
    conv = nn.Conv3d(6, 4, 3, padding=2, dilation=2, bias=False).double()
    x = torch.randn((2, 6, 5, 6, 7), dtype=torch.float64, requires_grad=True)
    y = wg.conv_with_gemm_weight_grad(x, conv.weight, 2)
    y_ref = conv(x)
    torch.testing.assert_close(y, y_ref, rtol=0, atol=0)
    grad = torch.randn_like(y)
    gx, gw = torch.autograd.grad(y, (x, conv.weight), grad)
    gx_ref, gw_ref = torch.autograd.grad(y_ref, (x, conv.weight), grad)
    torch.testing.assert_close(gx, gx_ref, rtol=0, atol=0)  # the input gradient is ATen's own
    torch.testing.assert_close(gw, gw_ref, rtol=1e-12, atol=1e-12)


def _used_on(net: SubFocalNet, monkeypatch, avx2: bool) -> list[nn.Module]:
    monkeypatch.setattr(wg, "_avx2_kernels", lambda: avx2)
    used: list[nn.Module] = []
    real = wg.conv_with_gemm_weight_grad
    monkeypatch.setattr(wg, "conv_with_gemm_weight_grad", lambda x, w, d: used.append(w) or real(x, w, d))
    net(torch.rand((1, 81, 8, 8)))[0].sum().backward()
    weights = {id(m.weight): m for m in net.modules() if isinstance(m, (nn.Conv2d, nn.Conv3d))}
    return [weights[id(w)] for w in used]


def test_auto_uses_it_only_on_the_layers_where_it_pays_and_only_with_avx2_kernels(monkeypatch):
    torch.manual_seed(0)
    net = SubFocalNet(width=2).train()
    assert _used_on(net, monkeypatch, avx2=False) == []
    used = _used_on(net, monkeypatch, avx2=True)
    expected = [m for m in net.modules() if isinstance(m, (nn.Conv2d, nn.Conv3d)) and wg.pays_off(m)]
    assert sorted(map(id, used)) == sorted(map(id, expected))
    # the 324-channel first 3D convolution and the four dilated 3x3 convolutions of layer 4
    assert net.aggregation.dres0a.conv in used and sum(isinstance(m, nn.Conv2d) for m in used) == 4
    net.set_training_path("fast", weight_grad="native")
    assert _used_on(net, monkeypatch, avx2=True) == []
    net.set_training_path("reference", weight_grad="gemm")
    assert _used_on(net, monkeypatch, avx2=True) == []  # the reference path keeps the original ops


def test_unknown_weight_grad_is_refused():
    with pytest.raises(ValueError, match="Unknown weight_grad 'fast'. Available: auto, gemm, native"):
        SubFocalNet(width=2).set_training_path("fast", weight_grad="fast")


def test_avx2_kernels_follow_atens_capability(monkeypatch):
    for capability, expected in (("AVX2", True), ("AVX512", False), ("DEFAULT", False)):
        monkeypatch.setattr(torch.backends.cpu, "get_cpu_capability", lambda c=capability: c)
        assert wg._avx2_kernels() is expected
