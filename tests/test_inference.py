"""SubFocal inference: exact tiling (== whole image), memory-budget tiles, outputs, bf16, registered methods."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from lfbench_methods.subfocal.inference import estimate_tile_bytes, infer, plan_tile, region_volume, tile_count
from lfbench_methods.subfocal.keras_import import save_checkpoint
from lfbench_methods.subfocal.method import SubFocal
from lfbench_methods.subfocal.network import SubFocalNet

from lfbench.cli import main
from lfbench.data.scene import ArrayLightField
from lfbench.method.registry import create, create_from_spec
from lfbench.utils.errors import DataError, SpecError

pytestmark = pytest.mark.usefixtures("one_torch_thread")  # small tensors: see conftest


def _net(seed: int = 0, **kw) -> SubFocalNet:
    torch.manual_seed(seed)
    net = SubFocalNet(**{"width": 4, **kw})
    g = torch.Generator().manual_seed(seed + 1)
    with torch.no_grad():  # non-trivial BN statistics so that eval-mode BN matters
        for name, buf in net.named_buffers():
            if name.endswith("running_mean"):
                buf.copy_(torch.randn(buf.shape, generator=g) * 0.1)
            elif name.endswith("running_var"):
                buf.copy_(torch.rand(buf.shape, generator=g) + 0.5)
    return net.eval()


def _views(h: int, w: int, seed: int = 0) -> torch.Tensor:
    return torch.rand((1, 81, h, w), generator=torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("mode", ["bilinear", "nearest", "phase"])
def test_region_volume_is_the_crop_of_the_whole_cost_volume(mode):
    net = _net(interpolation=mode, interval=1.0)
    with torch.inference_mode():
        feats = net.features(_views(20, 23))
        whole = net.cost_volume(feats)
        part = region_volume(net, feats, 3, 17, 5, 21, chunk_bytes=1e5)  # several disparity chunks
    assert part.shape == (1, 324, 9, 14, 16)
    assert (part - whole[..., 3:17, 5:21]).abs().max().item() <= (1e-6 if mode == "phase" else 0.0)


@pytest.mark.slow
@pytest.mark.parametrize("mode,grid", [("bilinear", (-4, 4, 0.5)), ("nearest", (-4, 4, 0.5)), ("phase", (-2, 2, 1))])
def test_tiled_inference_equals_whole_image_inference(mode, grid):
    net = _net(interpolation=mode, d_min=grid[0], d_max=grid[1], interval=grid[2])
    views = _views(48, 48)
    with torch.inference_mode():
        disp, prob = net(views)  # the plain whole-image forward pass (no tiling code involved)
    out = infer(net, views, tile=16)  # 9 tiles, halo 9 px
    assert tile_count(48, 48, 16) == 9
    assert (out.disparity - disp).abs().max().item() < 1e-4
    assert (out.probability - prob).abs().max().item() < 1e-4
    if mode != "bilinear":
        return
    # Non-square image and a tile size that does not divide it.
    views = _views(30, 41, seed=1)
    with torch.inference_mode():
        disp, _ = net(views)
    assert (infer(net, views[0], tile=13).disparity - disp).abs().max().item() < 1e-4


def test_a_short_halo_or_a_per_tile_attention_would_change_the_result():
    net = _net()
    views = _views(48, 48)
    with torch.inference_mode():
        disp, _ = net(views)
    short = infer(net, views, tile=16, halo=3)
    assert (short.disparity - disp).abs().max().item() > 1e-3  # tile seams show without the 9 px halo
    # Attention from one tile only differs from the whole-image mean: the accumulation matters.
    with torch.inference_mode():
        feats = net.features(views)
        whole_mean = net.cost_volume(feats).mean(dim=(2, 3, 4))
        tile_mean = region_volume(net, feats, 0, 16, 0, 16).mean(dim=(2, 3, 4))
        assert (net.attention_weights(whole_mean) - net.attention_weights(tile_mean)).abs().max() > 1e-3


@pytest.mark.slow
def test_memory_budget_picks_tiles_and_stays_exact():
    net = _net(width=8)
    whole_bytes = estimate_tile_bytes(net, 48, 48)
    assert plan_tile(net, 48, 48, max_memory_gb=100) == 48
    small = plan_tile(net, 48, 48, max_memory_gb=whole_bytes / 3e9)
    assert 8 <= small < 48 and small % 8 == 0
    assert estimate_tile_bytes(net, min(small + 18, 48), min(small + 18, 48)) <= whole_bytes / 3
    views = _views(48, 48, seed=2)
    with torch.inference_mode():
        disp, _ = net(views)
    out = infer(net, views, max_memory_gb=whole_bytes / 3e9)
    assert (out.disparity - disp).abs().max().item() < 1e-4
    # The paper network on a 512x512 scene does not fit 4 GB in one piece: it is tiled.
    paper = SubFocalNet()
    tile = plan_tile(paper, 512, 512, max_memory_gb=4)
    assert tile < 512 and estimate_tile_bytes(paper, tile + 18, tile + 18) < 4e9


def test_outputs_distribution_and_uncertainty():
    net = _net(interval=0.25, attention=False)
    out = infer(net, _views(12, 14))
    d = out.disparities.numpy().astype(np.float64)
    assert d.shape == (33,) and d[0] == -4 and d[-1] == 4
    p = out.probability[0].numpy().astype(np.float64)
    assert out.disparity.dtype == out.uncertainty.dtype == out.probability.dtype == torch.float32
    np.testing.assert_allclose(p.sum(0), 1.0, atol=1e-5)
    mean = np.einsum("k,khw->hw", d, p)
    np.testing.assert_allclose(out.disparity[0].numpy(), mean, atol=1e-5)
    std = np.sqrt(np.einsum("khw,khw->hw", p, (d[:, None, None] - mean) ** 2))
    np.testing.assert_allclose(out.uncertainty[0].numpy(), std, atol=1e-5)
    # A one-hot distribution has zero spread; a two-bin 50/50 split has a spread of half a step.
    cost = torch.full((1, 33, 1, 2), -1e4)
    cost[0, 20, 0, 0] = 0.0
    cost[0, 20:22, 0, 1] = 0.0
    from lfbench_methods.subfocal.inference import distribution_std

    disp, prob = net.regress(cost)
    spread = distribution_std(prob, net.disparities, disp)
    assert disp[0, 0, 0].item() == pytest.approx(1.0) and spread[0, 0, 0].item() == pytest.approx(0.0, abs=1e-6)
    assert disp[0, 0, 1].item() == pytest.approx(1.125) and spread[0, 0, 1].item() == pytest.approx(0.125)


def test_bf16_autocast_is_close_to_fp32(cpu_bf16):
    net = _net(width=8)
    views = _views(24, 24)
    fp32 = infer(net, views)
    bf16 = infer(net, views, precision="bf16", tile=12)
    assert bf16.disparity.dtype == torch.float32
    diff = (bf16.disparity - fp32.disparity).abs()
    assert diff.max().item() < 0.1 and diff.mean().item() < 0.02
    with pytest.raises(ValueError):
        infer(net, views, precision="fp16")


# -- the registered methods ----------------------------------------------------------------------

@pytest.fixture()
def no_default_weights(monkeypatch, tmp_path: Path):
    monkeypatch.setattr(SubFocal, "WEIGHTS_DIR", tmp_path / "absent")  # no <variant>_small.pt of any variant


def test_subfocal_method_predicts_with_a_checkpoint(tmp_path: Path):
    net = _net(width=3)
    ckpt = tmp_path / "small.pt"
    save_checkpoint(net, ckpt, source="test")
    views = _views(20, 18, seed=4)
    lf = ArrayLightField(views=views[0].reshape(9, 9, 20, 18).numpy(), name="toy")
    method = create_from_spec(f"subfocal:weights={ckpt},tile=8,threads=1")
    assert method.available_for(lf) is None
    pred = method.run(lf)
    with torch.inference_mode():
        disp, prob = net(views)
    np.testing.assert_allclose(pred.disparity, disp[0].numpy(), atol=1e-4)
    assert pred.distribution.shape == (17, 20, 18) and pred.disparity_values.shape == (17,)
    assert pred.uncertainty.shape == (20, 18) and np.all(pred.uncertainty >= 0)
    assert method.describe_variant()["width"] == 3
    # The checkpoint's config decides the architecture; a contradicting explicit parameter is refused.
    with pytest.raises(SpecError, match="width=5"):
        create("subfocal", weights=ckpt, width=5).predict(lf)
    with pytest.raises(SpecError, match="interval"):
        create_from_spec(f"subfocal:weights={ckpt},interval=0.25").describe_variant()
    assert create("subfocal", weights=ckpt, width=3, interval=0.5).load_network() is not None


def test_missing_weights_are_reported_never_random(no_default_weights, tmp_path: Path):
    lf = ArrayLightField(views=np.zeros((9, 9, 8, 8), np.float32))
    for name in ("subfocal", "lfattnet"):
        method = create(name)
        reason = method.available_for(lf)
        assert reason and "\n" not in reason and "weights" in reason
        with pytest.raises(DataError):
            method.predict(lf)
    explicit = create("subfocal", weights=tmp_path / "nope.pt")
    assert "not found" in explicit.available_for(lf)
    junk = tmp_path / "junk.pt"
    junk.write_text("not a checkpoint")
    with pytest.raises(DataError, match="not a torch checkpoint"):
        create("subfocal", weights=junk).predict(lf)
    with pytest.raises(SpecError):
        create_from_spec("subfocal:interval=0.3")  # 8 / 0.3 is not a whole number of steps
    with pytest.raises(SpecError):
        create_from_spec("subfocal:interpolation=cubic")


def test_info_prints_trainable_parameters_of_the_configured_variant(no_default_weights, capsys):
    assert main(["info", "subfocal"]) == 0
    out = capsys.readouterr().out
    assert "trainable_parameters: 5055329" in out and "disparities: 17" in out
    assert main(["info", "subfocal:interval=0.1"]) == 0
    out = capsys.readouterr().out
    assert "trainable_parameters: 5055329" in out and "disparities: 81" in out
    assert main(["info", "lfattnet"]) == 0
    out = capsys.readouterr().out
    assert "trainable_parameters: 5055329" in out and "disparities: 9" in out
    assert main(["info", "subfocal:width=16,attention=false"]) == 0
    assert "trainable_parameters: 216260" in capsys.readouterr().out  # 34164 + 27*(324*16+6*256+16) + 224


def test_shipped_weights_serve_only_their_own_architecture(monkeypatch, tmp_path: Path, capsys):
    shipped = tmp_path / "subfocal_small.pt"
    save_checkpoint(_net(width=3), shipped, source="shipped test model")
    monkeypatch.setattr(SubFocal, "WEIGHTS_DIR", tmp_path)
    lf = ArrayLightField(views=_views(12, 12, seed=5)[0].reshape(9, 9, 12, 12).numpy(), name="toy")
    assert create("subfocal").offline_variants() == [{"width": 3}]
    assert create("lfattnet").offline_variants() == []  # no lfattnet_small.pt
    small = create_from_spec("subfocal:width=3,threads=1")
    assert small.weights_path == shipped and small.available_for(lf) is None
    assert small.run(lf).disparity.shape == (12, 12)
    paper = create("subfocal")  # the paper's architecture: the small checkpoint must not be used for it
    assert paper.weights_path is None
    assert "subfocal:width=3" in paper.available_for(lf)
    assert main(["info", "subfocal"]) == 0
    out = capsys.readouterr().out
    assert "trainable_parameters: 5055329" in out and "weights: none" in out
    assert main(["info", "subfocal:width=3"]) == 0
    out = capsys.readouterr().out
    assert f"weights: {shipped} (shipped; source shipped test model)" in out
