"""DistgDisp (methods/distgdisp): the authors' network, checked against independent computations.

- the trainable-parameter count is the one the authors' layer list gives (counted here by hand), and the
  SubFocal paper's 4.89 M is that count without the DSAFE kernel;
- a state_dict with the authors' key names (written out here from their module layout) loads from a
  ``{'state_dict': ...}`` .pth.tar, and files of another network, another size or a truncated one are one line;
- the DSAFE dilation and padding per disparity are the hand-worked values, and on a macro-pixel image of a
  constant-disparity plane (views made with lfbench's sign) the authors' cost construction has its minimum
  at that disparity: their sign is lfbench's;
- the fast path equals the authors' computation on the MacPI (methods/distgdisp/reference.py) for 9x9, 7x7
  and 5x5 views, in eval and training mode; exact tiles equal the whole image; bf16 is close to fp32.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from lfbench_methods.distgdisp.network import DistgDispNet, count_trainable, disparity_range, dsafe_geometry
from lfbench_methods.distgdisp.reference import (
    macpi_cost_volume,
    random_batch_norm,
    reference_forward,
    sai_array,
    sai_to_macpi,
)

from lfbench.data.scene import ArrayLightField
from lfbench.method.trainable import get_trainable
from lfbench.utils.errors import DataError
from lfbench.utils.hardware import bf16_unavailable


def _randomise(net: DistgDispNet, seed: int = 0) -> DistgDispNet:
    """Random BatchNorm terms, and a sharper last layer: disparities that differ from pixel to pixel."""
    random_batch_norm(net, seed)
    with torch.no_grad():
        net.aggregation[-1].weight.mul_(20.0)
    return net


def _small(angular: int = 5, d_min: float = -2, d_max: float = 2, features: int = 4, channels: int = 6,
           seed: int = 0) -> DistgDispNet:
    torch.manual_seed(seed)
    return _randomise(DistgDispNet(angular=angular, d_min=d_min, d_max=d_max, features=features, channels=channels),
                      seed)


# -- the authors' layers ------------------------------------------------------------------------------


def authors_parameter_count(a: int = 9, f: int = 16, c: int = 160) -> int:
    """Trainable parameters of the authors' Net(angRes=a) counted from their layer list: init_feature (conv
    1->f, BN, conv f->f, BN, 8 SpaResB of two conv+BN, conv+BN, conv), DSAFE (c x f x a x a), aggregation
    (two conv3d+BN, 2 ResB3D of two conv3d+BN, conv3d+BN, conv3d c->1); all convolutions without bias."""
    conv2 = f * f * 9
    bn2 = 2 * f
    features = f * 1 * 9 + bn2 + conv2 + bn2 + 8 * 2 * (conv2 + bn2) + conv2 + bn2 + conv2
    dsafe = c * f * a * a
    conv3 = c * c * 27
    bn3 = 2 * c
    aggregation = 2 * (conv3 + bn3) + 2 * 2 * (conv3 + bn3) + (conv3 + bn3) + c * 27
    return features + dsafe + aggregation


def authors_keys(a: int = 9) -> set[str]:
    """The authors' state_dict keys, from their module layout (nn.Sequential indices; LeakyReLU holds none)."""
    bn = ("weight", "bias", "running_mean", "running_var", "num_batches_tracked")
    keys = {"build_costvolume.DSAFE.weight"}

    def conv_bn(prefix: str, conv: int) -> None:
        keys.add(f"{prefix}.{conv}.weight")
        keys.update(f"{prefix}.{conv + 1}.{k}" for k in bn)

    conv_bn("init_feature", 0)
    conv_bn("init_feature", 3)
    for block in range(6, 14):
        conv_bn(f"init_feature.{block}.body", 0)
        conv_bn(f"init_feature.{block}.body", 3)
    conv_bn("init_feature", 14)
    keys.add("init_feature.17.weight")
    conv_bn("aggregation", 0)
    conv_bn("aggregation", 3)
    for block in (6, 7):
        conv_bn(f"aggregation.{block}.body", 0)
        conv_bn(f"aggregation.{block}.body", 3)
    conv_bn("aggregation", 8)
    keys.add("aggregation.11.weight")
    return keys


def test_parameter_count_is_the_authors_and_the_papers_4_89_m_leaves_out_dsafe():
    net = DistgDispNet()
    n = count_trainable(net)
    assert n == authors_parameter_count() == 5_096_848
    # The SubFocal paper's Table III (and DistgDisp's own) gives 4.89 M: the count without the DSAFE kernel,
    # which the authors apply through F.conv2d (a counter that hooks called modules, e.g. thop, misses it).
    dsafe = net.build_costvolume.DSAFE.weight.numel()
    assert dsafe == 160 * 16 * 81
    assert round((n - dsafe) / 1e6, 2) == 4.89 and round(n / 1e6, 2) == 5.10
    for a in (7, 5):
        assert count_trainable(DistgDispNet(angular=a)) == authors_parameter_count(a)


def test_state_dict_keys_are_the_authors():
    assert set(DistgDispNet().state_dict()) == authors_keys()


def _authors_file(tmp_path, state: dict, name: str = "DistgDisp.pth.tar"):
    path = tmp_path / name
    torch.save({"epoch": 3000, "state_dict": state}, path)
    return path


@pytest.mark.slow  # builds the paper-size network twice (~15 s on 2 shared cores)
def test_an_authors_checkpoint_loads_and_runs_as_released(tmp_path):
    ref = _small(angular=9, d_min=-4, d_max=4, features=16, channels=160)
    path = _authors_file(tmp_path, {k: v.clone() for k, v in ref.state_dict().items()})
    trainable = get_trainable("distgdisp")
    assert trainable.stored_config(path) == {"angular": 9, "d_min": -4.0, "d_max": 4.0, "features": 16,
                                             "channels": 160}
    net = trainable.load(path)
    for key, value in ref.state_dict().items():
        assert torch.equal(net.state_dict()[key], value), key
    assert net.disparities.tolist() == list(range(-4, 5))
    # through the method, on a small light field (a small network in the authors' format)
    from lfbench.method.registry import create_from_spec

    small = _small(angular=9, d_min=-4, d_max=4)
    path = _authors_file(tmp_path, small.state_dict(), "small.pth.tar")
    method = create_from_spec(f"distgdisp:weights={path},device=cpu")
    lf = ArrayLightField(np.random.default_rng(0).random((9, 9, 12, 14), dtype=np.float32), name="lf")
    pred = method.predict(lf)
    views = torch.from_numpy(lf.gray_views().reshape(1, 81, 12, 14))
    expected, prob = reference_forward(small.eval(), views)
    np.testing.assert_allclose(pred.disparity, expected[0].numpy(), atol=1e-4)
    np.testing.assert_allclose(pred.distribution, prob[0].numpy(), atol=1e-5)


def test_dataparallel_prefix_and_other_angular_sizes(tmp_path):
    ref = _small(angular=7, d_min=-4, d_max=4)
    path = _authors_file(tmp_path, {"module." + k: v for k, v in ref.state_dict().items()})
    config = get_trainable("distgdisp").stored_config(path)
    assert (config["angular"], config["features"], config["channels"]) == (7, 4, 6)
    get_trainable("distgdisp").load(path)


@pytest.mark.parametrize(("state", "fragment"), [
    ({"feature_extraction.0.weight": torch.zeros(3)},
     "not DistgDisp's (its first key is 'feature_extraction.0.weight')"),
    ({"build_costvolume.DSAFE.weight": torch.zeros(160, 16, 9)}, "not DistgDisp's (channels, features, A, A)"),
])
def test_foreign_authors_files_are_one_line_naming_the_file(tmp_path, state, fragment):
    path = _authors_file(tmp_path, state)
    with pytest.raises(DataError) as err:
        get_trainable("distgdisp").load(path)
    assert fragment in str(err.value) and str(path) in str(err.value)


def test_missing_tensors_and_truncated_files(tmp_path):
    state = _small(angular=9, d_min=-4, d_max=4).state_dict()
    del state["aggregation.11.weight"]
    with pytest.raises(DataError, match="missing 1 tensors"):
        get_trainable("distgdisp").load(_authors_file(tmp_path, state, "part.pth.tar"))
    whole = _authors_file(tmp_path, _small().state_dict(), "whole.pth.tar").read_bytes()
    cut = tmp_path / "cut.pth.tar"
    cut.write_bytes(whole[: len(whole) // 2])
    with pytest.raises(DataError, match="not a readable torch checkpoint"):
        get_trainable("distgdisp").load(cut)


def test_another_angular_size_than_the_spec_says_is_one_line(tmp_path):
    from lfbench.method.registry import create_from_spec
    from lfbench.utils.errors import SpecError

    path = _authors_file(tmp_path, _small(angular=9, d_min=-4, d_max=4).state_dict())
    method = create_from_spec(f"distgdisp:weights={path},angular=7,device=cpu")
    with pytest.raises(SpecError, match=r"angular=7 \(checkpoint: 9\)"):
        method.load_network()


# -- DSAFE: dilation and padding per disparity, the cost minimum, the sign ---------------------------------


def test_dsafe_dilation_and_padding_by_hand():
    # A = 5: d < 0: dilation |d| A + 1, padding A (A - 1) |d| / 2; d > 0: d A - 1, A (A - 1) d / 2 - A + 1
    assert [dsafe_geometry(d, 5) for d in (-2, -1, 0, 1, 2)] == [(11, 20), (6, 10), (1, 0), (4, 6), (9, 16)]
    assert [dsafe_geometry(d, 9) for d in (-1, 1, 4)] == [(10, 36), (8, 28), (35, 136)]
    # the output of every one is H x W again: (H A + 2 pad - dilation (A - 1) - 1) // A + 1 = H
    for a in (5, 7, 9):
        for d in range(-4, 5):
            dil, pad = dsafe_geometry(d, a)
            assert (11 * a + 2 * pad - dil * (a - 1) - 1) // a + 1 == 11


def plane_views(d: int, angular: int, h: int = 36, w: int = 38, seed: int = 0) -> torch.Tensor:
    """(1, N, h, w) views of a textured plane at integer disparity ``d`` with lfbench's sign: the centre's
    point (x, y) appears in view (row r, column s) at (x - (s - c) d, y - (r - c) d)."""
    c = angular // 2
    pad = c * abs(d)
    tex = np.random.default_rng(seed).random((h + 2 * pad, w + 2 * pad)).astype(np.float32)
    views = np.empty((angular, angular, h, w), np.float32)
    for r in range(angular):
        for s in range(angular):
            y0, x0 = pad + (r - c) * d, pad + (s - c) * d
            views[r, s] = tex[y0:y0 + h, x0:x0 + w]
    return torch.from_numpy(views.reshape(1, angular * angular, h, w))


def _difference_kernel(angular: int) -> torch.Tensor:
    """DSAFE weights (N, 1, A, A): output channel k = centre tap - tap k (tap k = view k for d <= 0; the
    set of all taps is the set of all views for every d)."""
    n, c = angular * angular, angular // 2
    w = torch.zeros(n, 1, angular, angular)
    for k in range(n):
        w[k, 0, c, c] += 1.0
        w[k, 0, k // angular, k % angular] -= 1.0
    return w


@pytest.mark.parametrize(("angular", "true_d"), [(9, 1), (9, -2), (7, 2), (5, -1), (5, 0)])
def test_macpi_cost_of_a_constant_disparity_plane_is_least_at_its_disparity(angular, true_d):
    """The authors' cost construction (strided, dilated convolution on the MacPI), fed the views themselves
    as features and a kernel of differences with the centre: the summed |difference| vanishes inside the
    image at the plane's disparity and nowhere else, so their disparity sign is lfbench's."""
    net = DistgDispNet(angular=angular, d_min=-3, d_max=3, features=1, channels=angular * angular)
    with torch.no_grad():
        net.build_costvolume.DSAFE.weight.copy_(_difference_kernel(angular))
    views = plane_views(true_d, angular)
    macpi = sai_to_macpi(sai_array(views, angular), angular)
    cost = macpi_cost_volume(net, macpi)  # (1, N, D, H, W)
    b = (angular // 2) * 3
    err = cost.abs().sum(1)[0, :, b:-b, b:-b].mean(dim=(1, 2))
    grid = net.disparities.tolist()
    assert grid[int(err.argmin())] == true_d
    assert err[grid.index(true_d)] < 1e-5 and (err[[i for i, d in enumerate(grid) if d != true_d]] > 0.05).all()
    # the network's own cost volume is the same numbers
    with torch.no_grad():
        ours = net.build_costvolume(views.reshape(angular * angular, 1, *views.shape[2:]))
    torch.testing.assert_close(ours, cost, atol=1e-5, rtol=1e-5)
    # and the soft argmin over a sharpened negative cost returns the plane's disparity (lfbench's sign)
    with torch.no_grad():
        disp, _ = net.regression(-50.0 * err[None, :, None, None], net.disparities)
    assert abs(float(disp) - true_d) < 1e-3


@pytest.mark.parametrize("d", [-2, 1, 2])
def test_one_tap_reads_the_hand_worked_view_and_pixel(d):
    """Tap (i, j) alone: at d <= 0 it reads view (i, j), at d > 0 view (A - 1 - i, A - 1 - j), at pixel
    (h - d (u - c), w - d (v - c)), zero outside (the authors' padding, worked out by hand)."""
    a, c, h, w = 5, 2, 9, 10
    i, j = 0, 1
    net = DistgDispNet(angular=a, d_min=-2, d_max=2, features=1, channels=1)
    k = net.disparities.tolist().index(d)
    with torch.no_grad():
        net.build_costvolume.DSAFE.weight.zero_()
        net.build_costvolume.DSAFE.weight[0, 0, i, j] = 1.0
    views = torch.rand(1, a * a, h, w)
    cost = macpi_cost_volume(net, sai_to_macpi(sai_array(views, a), a))[0, 0, k]
    u, v = (i, j) if d <= 0 else (a - 1 - i, a - 1 - j)
    expected = torch.zeros(h, w)
    for y in range(h):
        for x in range(w):
            yy, xx = y - d * (u - c), x - d * (v - c)
            if 0 <= yy < h and 0 <= xx < w:
                expected[y, x] = views[0, u * a + v, yy, xx]
    torch.testing.assert_close(cost, expected)
    with torch.no_grad():
        ours = net.build_costvolume(views.reshape(a * a, 1, h, w))[0, 0, k]
    torch.testing.assert_close(ours, expected)


def test_integer_grid_follows_the_dataset_range():
    assert disparity_range(-0.5, 1.6) == (-1, 2)  # UrbanLF-Syn's range: Table III's [-1, 2]
    assert disparity_range(-4, 4) == (-4, 4) and disparity_range(-2, 2) == (-2, 2)
    assert DistgDispNet(d_min=-0.5, d_max=1.6, features=2, channels=2).disparities.tolist() == [-1, 0, 1, 2]
    with pytest.raises(ValueError, match="angular must be odd"):
        DistgDispNet(angular=8)


# -- the network against the authors' computation ---------------------------------------------------------


@pytest.mark.parametrize(("angular", "d_min", "d_max"), [(9, -1, 2), (7, -2, 2), (5, -4, 4)])
def test_network_equals_the_authors_computation_on_the_macpi(angular, d_min, d_max):
    net = _small(angular, d_min, d_max).eval()
    views = torch.rand(2, angular * angular, 13, 15, generator=torch.Generator().manual_seed(1))
    expected, prob = reference_forward(net, views)
    assert expected.std() > 0.05  # a map that varies: a wrong shift or tap would show
    with torch.no_grad():
        fast, fast_prob = net(views)  # folded BatchNorm, channels-last
        net.fast_inference = False
        plain, _ = net(views)
    torch.testing.assert_close(fast, expected, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(fast_prob, prob, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(plain, expected, atol=1e-5, rtol=1e-5)
    net.train()  # training mode: BatchNorm's batch statistics over the MacPI are those over all views
    trained, _ = net(views)
    expected_train, _ = reference_forward(net, views)
    torch.testing.assert_close(trained.detach(), expected_train, atol=1e-4, rtol=1e-4)  # batch statistics: other sums


@pytest.mark.parametrize("block_values", [1, 3 * 15 * 25 * 4, 10**9])  # one row, 3 rows, the whole image
def test_the_cost_volume_made_a_block_of_rows_at_a_time_is_the_one_product_per_disparity(monkeypatch, block_values):
    """Inference builds the DSAFE cost volume a few rows at a time (the stacked views stay in the cache); each
    sample of a batch and each block must be the rows of the autograd path's one product per disparity."""
    import lfbench_methods.distgdisp.network as network

    net = _small(5, -2, 1).eval()
    feats = torch.rand(2 * 25, 4, 13, 15, generator=torch.Generator().manual_seed(5))
    net.build_costvolume.DSAFE = torch.nn.Conv2d(4, 6, 5, stride=5, bias=False)
    with torch.enable_grad():
        expected = net.build_costvolume(feats.requires_grad_()).detach()
    feats = feats.detach()
    monkeypatch.setattr(network, "STACK_BLOCK_VALUES", block_values)
    with torch.no_grad():
        blocks = net.build_costvolume(feats)
    assert blocks.shape == expected.shape == (2, 6, 4, 13, 15)
    torch.testing.assert_close(blocks, expected, atol=1e-6, rtol=1e-6)
    assert not torch.equal(blocks[0], blocks[1])  # the two samples are not one repeated


def test_exact_tiles_equal_the_whole_image():
    net = _small(5, -1, 1).eval()
    trainable = get_trainable("distgdisp")
    assert trainable.receptive_radius(net) == 20 + 2 * 1 + 8
    views = torch.rand(1, 25, 26, 23, generator=torch.Generator().manual_seed(2))
    whole, p_whole = trainable.infer(net, views)
    tiled, p_tiled = trainable.infer(net, views, tile=9)  # 3 x 3 tiles, each with up to 30 px of context
    torch.testing.assert_close(tiled, whole, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(p_tiled, p_whole, atol=1e-5, rtol=1e-5)
    # the radius is needed: with less context the tiles' borders differ
    from lfbench.method.trainable import tiled_forward

    with torch.inference_mode():
        short, _ = tiled_forward(net, views, 9, 3)
    assert (short - whole).abs().max() > 1e-4


def test_bf16_is_close_to_fp32():
    reason = bf16_unavailable(torch.device("cpu"))
    if reason:
        pytest.skip(reason)
    net = _small(5, -2, 2, features=8, channels=16).eval()
    views = torch.rand(1, 25, 24, 24, generator=torch.Generator().manual_seed(3))
    trainable = get_trainable("distgdisp")
    fp32, _ = trainable.infer(net, views)
    bf16, prob = trainable.infer(net, views, precision="bf16")
    assert prob.dtype == torch.float32
    assert (bf16.float() - fp32).abs().mean() < 0.05


def test_flops_count_the_layers():
    net = DistgDispNet()
    f = net.flops(256, 256)
    px, d = 256 * 256, 9
    assert f["cost_volume"] == 2 * d * px * 160 * 16 * 81
    assert f["aggregation"] == 2 * d * px * (7 * 160 * 160 * 27 + 160 * 27)
    assert f["features"] == 2 * 81 * px * (16 * 9 + 19 * 16 * 16 * 9)
    assert f["total"] == f["cost_volume"] + f["aggregation"] + f["features"]


def test_authors_gray_is_the_mean_of_rgb():
    class RGB:
        def rgb_views(self):
            return np.stack([np.full((3, 3, 2, 2), v, np.float32) for v in (0.0, 0.3, 0.9)], axis=-1)

    views = get_trainable("distgdisp").views_of(RGB())
    np.testing.assert_allclose(views, 0.4, atol=1e-7)


@pytest.mark.slow  # ~30 s idle; minutes on the loaded 2-core machine (every check runs the network)
def test_check_plugin_is_green():
    from lfbench.runs.plugin_check import FAIL, check_plugin

    findings = check_plugin("distgdisp", {"angular": 5, "features": 2, "channels": 4, "d_min": -1, "d_max": 1})
    assert not [f.line() for f in findings if f.status == FAIL]
    assert {f.check for f in findings if f.status == "ok"} >= {"build", "forward", "receptive_radius", "tiling",
                                                               "flops", "save/load", "training"}


# -- training ----------------------------------------------------------------------------------------------


@pytest.mark.slow  # ~20 s idle (synthetic scenes, 3 steps, a validation pass)
def test_training_smoke_run_learns_and_its_weights_run(tmp_path):
    """A few steps of lfbench train with the authors' recipe scaled down (configs/distgdisp_cpu_smoke.toml's
    pipeline): finite losses, and final.pt rebuilds the network it trained (that one step changes every
    parameter is check-plugin's training check, test_check_plugin_is_green)."""
    from lfbench.training.config import TrainConfig
    from lfbench.training.loop import train

    raw = {
        "seed": 3, "method": "distgdisp",
        "data": {"train": ["smoke"], "validation": ["smoke_val"], "patch": 16, "strides": [1], "stride_weights": [1],
                 "synthetic": [{"category": "smoke", "seed": 1, "size": 32, "scenes": 2},
                               {"category": "smoke_val", "seed": 2, "size": 32, "scenes": 1}]},
        "model": {"d_min": -2.0, "d_max": 2.0, "features": 2, "channels": 4},
        "training": {"batch_size": 2, "threads": 1, "device": "cpu", "checkpoint_every": 2, "log_every": 1,
                     "prefetch": 0},
        "validation": {"every": 0, "border": 4},
        "stages": [{"name": "l1", "loss": "l1", "lr": 1e-3, "eps": 1e-8, "steps": 3}],
    }
    out = tmp_path / "run"
    cfg = TrainConfig.from_dict(raw)
    train(cfg, out, progress=False, command="test")
    trainable = get_trainable("distgdisp")
    net = trainable.load(out / "final.pt")
    assert trainable.stored_config(out / "final.pt") == {"angular": 9, "d_min": -2.0, "d_max": 2.0, "features": 2,
                                                          "channels": 4}
    views = torch.rand(1, 81, 12, 12)
    disparity, _ = trainable.infer(net, views)
    assert disparity.shape == (1, 12, 12) and torch.isfinite(disparity).all()
    import json

    lines = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    losses = [x["loss"] for x in lines if "loss" in x]
    assert losses and all(np.isfinite(losses))
