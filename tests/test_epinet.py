"""EPINET (methods/epinet): the authors' network (parameter count from their Keras layers), their view stacks,
the border lfbench fills, the import of their Keras checkpoints (a file written here with h5py as Keras 2
lays one out) against an independent numpy forward pass, refused checkpoints, exact tiles, bf16, and the
training margin."""

from __future__ import annotations

import contextlib
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from lfbench_methods.epinet.network import EPINet, count_trainable, stack_views

from lfbench.cli import main
from lfbench.method.trainable import crop_margin, get_trainable, tiled_forward
from lfbench.utils.errors import DataError

BN_EPS = 1e-3  # Keras BatchNormalization's default epsilon


def keras_parameter_count(views: int = 9, filt_num: int = 70, conv_depth: int = 7) -> int:
    """Trainable parameters of the authors' define_epinet, layer by layer (Conv2D 2x2 with bias; BN gamma and
    beta trainable, its moving statistics not)."""
    def conv(cin: int, cout: int) -> int:
        return 2 * 2 * cin * cout + cout

    def bn(c: int) -> int:
        return 2 * c

    stream = sum(conv(views if i == 0 else filt_num, filt_num) + conv(filt_num, filt_num) + bn(filt_num)
                 for i in range(3))  # layer1_multistream: for i in range(3)
    merged = conv_depth * (2 * conv(4 * filt_num, 4 * filt_num) + bn(4 * filt_num))  # layer2_merged
    last = conv(4 * filt_num, 4 * filt_num) + conv(4 * filt_num, 1)  # layer3_last
    return 4 * stream + merged + last


def test_parameter_count_is_the_authors():
    assert keras_parameter_count() == 5_118_681  # 4 x 101,360 + 7 x 628,320 + 313,880 + 1,121
    with torch.device("meta"):
        net = EPINet()
    assert count_trainable(net) == keras_parameter_count()
    for angular in (7, 5):
        with torch.device("meta"):
            assert count_trainable(EPINet(angular=angular)) == keras_parameter_count(views=angular)
    assert get_trainable("epinet").parameters()["filters"].default == 70


def test_margin_and_receptive_radius_of_the_paper_network():
    with torch.device("meta"):
        net = EPINet()
    # 3 stream blocks + 7 merged blocks of two 2x2 valid convs, then two: 22 px lost in all, 11 per side
    assert net.output_margin == 11 and net.receptive_radius == 22


def test_stacks_are_the_authors_views_in_their_order():
    # func_makeinput.py, for input_Cam000 .. 080 (row-major; lfbench's view k is input_Cam{k:03d}):
    # seqLtoR = range(4, 81, 9)[::-1], seqUtoD = range(36, 45), seq5c = range(8, 80, 8)[::-1],
    # seq7c = range(0, 81, 10), fed in this order (the training code's 90d, 0d, 45d, m45d)
    assert stack_views(9) == {"90d": [76, 67, 58, 49, 40, 31, 22, 13, 4],
                              "0d": [36, 37, 38, 39, 40, 41, 42, 43, 44],
                              "45d": [72, 64, 56, 48, 40, 32, 24, 16, 8],
                              "m45d": [0, 10, 20, 30, 40, 50, 60, 70, 80]}
    assert stack_views(5) == {"90d": [22, 17, 12, 7, 2], "0d": [10, 11, 12, 13, 14],
                              "45d": [20, 16, 12, 8, 4], "m45d": [0, 6, 12, 18, 24]}
    assert stack_views(7)["45d"] == [42, 36, 30, 24, 18, 12, 6]
    net = EPINet(angular=5, filters=1, depth=0)
    views = torch.arange(25.0).view(1, 25, 1, 1).expand(2, 25, 3, 4)
    got = [s[0, :, 0, 0].tolist() for s in net.stacks(views)]
    assert got == [[22, 17, 12, 7, 2], [10, 11, 12, 13, 14], [20, 16, 12, 8, 4], [0, 6, 12, 18, 24]]
    with pytest.raises(ValueError, match="odd"):
        EPINet(angular=8)


# -- an independent numpy EPINET on the authors' Keras arrays ---------------------------------------------


def keras_arrays(angular: int, filters: int, depth: int, seed: int) -> dict:
    """Random weights in Keras layouts (kernel (2, 2, in, out)), BN statistics included."""
    rng = np.random.default_rng(seed)

    def conv(cin, cout):
        return {"kernel": rng.normal(0, 1 / np.sqrt(4 * cin), (2, 2, cin, cout)).astype(np.float32),
                "bias": rng.normal(0, 0.1, cout).astype(np.float32)}

    def bn(c):
        return {"gamma": rng.uniform(0.5, 1.5, c).astype(np.float32), "beta": rng.normal(0, 0.2, c).astype(np.float32),
                "moving_mean": rng.normal(0, 0.3, c).astype(np.float32),
                "moving_variance": rng.uniform(0.5, 2.0, c).astype(np.float32)}

    def block(cin, cout):
        return {"c1": conv(cin, cout), "c2": conv(cout, cout), "BN": bn(cout)}

    w = 4 * filters
    return {"streams": [[block(angular if i == 0 else filters, filters) for i in range(3)] for _ in range(4)],
            "merged": [block(w, w) for _ in range(depth)], "last": {"c1": conv(w, w), "last": conv(w, 1)}}


def np_conv(x: np.ndarray, p: dict) -> np.ndarray:
    """Keras Conv2D 2x2 'valid' on (H, W, C): out[i, j] = sum_ab x[i + a, j + b] @ kernel[a, b] + bias."""
    h, w = x.shape[0] - 1, x.shape[1] - 1
    return sum(x[a:a + h, b:b + w] @ p["kernel"][a, b] for a in range(2) for b in range(2)) + p["bias"]


def np_block(x: np.ndarray, p: dict) -> np.ndarray:
    y = np_conv(np.maximum(np_conv(x, p["c1"]), 0), p["c2"])
    bn = p["BN"]
    y = bn["gamma"] * (y - bn["moving_mean"]) / np.sqrt(bn["moving_variance"] + BN_EPS) + bn["beta"]
    return np.maximum(y, 0)


def np_epinet(grid: np.ndarray, arrays: dict) -> np.ndarray:
    """The authors' inference on a (V, U, H, W) grey light field: their stacks (func_generate_traindata.py's
    indexing of traindata_all[..., row, col]: 90d rows 8..0 at the centre column, 0d the centre row, 45d
    (8 - k, k), m45d (k, k)), the streams, concatenate, merged blocks, last layers -> (H - 22, W - 22)."""
    a = grid.shape[0]
    c = a // 2
    stacks = [[grid[a - 1 - k, c] for k in range(a)], [grid[c, k] for k in range(a)],
              [grid[a - 1 - k, k] for k in range(a)], [grid[k, k] for k in range(a)]]
    feats = []
    for stack, blocks in zip(stacks, arrays["streams"], strict=True):
        x = np.stack(stack, axis=-1).astype(np.float64)
        for p in blocks:
            x = np_block(x, p)
        feats.append(x)
    x = np.concatenate(feats, axis=-1)
    for p in arrays["merged"]:
        x = np_block(x, p)
    return np_conv(np.maximum(np_conv(x, arrays["last"]["c1"]), 0), arrays["last"]["last"])[..., 0]


def write_keras_epinet(path: Path, arrays: dict, numbers: tuple[int, ...] = (1, 2, 3, 4, 5, 6), dup: int = 0,
                       layer_sep: str = "") -> None:
    """An HDF5 file as Keras 2's model.save writes define_epinet's model (model_weights/, layer_names, one group
    per layer, the Sequential sub-models' arrays at '<layer>/<weight>:0' listed in weight_names). ``numbers``:
    the Sequential models' creation numbers; ``dup``: TensorFlow's suffix of the first stream's layer names
    (stream s gets _<dup + s>, none for 0); ``layer_sep``: '' for S1_c10 (the authors'), '_' for S1_c1_0."""
    def layer(name: str, s: int = 0) -> str:
        n = dup + s
        return name if n == 0 else f"{name}_{n}"

    def block_weights(stage: str, i: int, p: dict, s: int) -> list[tuple[str, np.ndarray]]:
        out = []
        for kind, keys in (("c1", ("kernel", "bias")), ("c2", ("kernel", "bias")),
                           ("BN", ("gamma", "beta", "moving_mean", "moving_variance"))):
            out += [(f"{layer(f'{stage}_{kind}{layer_sep}{i}', s)}/{k}:0", p[kind][k]) for k in keys]
        return out

    seqs = [f"sequential_{n}" for n in numbers]
    groups: dict[str, list[tuple[str, np.ndarray]]] = {}
    for s, blocks in enumerate(arrays["streams"]):
        groups[seqs[s]] = [w for i, p in enumerate(blocks) for w in block_weights("S1", i, p, s)]
    groups[seqs[4]] = [w for i, p in enumerate(arrays["merged"]) for w in block_weights("S2", i, p, 0)]
    last = arrays["last"]
    groups[seqs[5]] = [(f"{layer(f'S3_c1{layer_sep}0')}/kernel:0", last["c1"]["kernel"]),
                       (f"{layer(f'S3_c1{layer_sep}0')}/bias:0", last["c1"]["bias"]),
                       (f"{layer('S3_last')}/kernel:0", last["last"]["kernel"]),
                       (f"{layer('S3_last')}/bias:0", last["last"]["bias"])]
    inputs = ["input_stack_LtoRb", "input_stack_UtoDb", "input_stack_5cb", "input_stack_7cb"]
    names = inputs + seqs[:4] + ["mid_LRUDa"] + seqs[4:]
    with h5py.File(path, "w") as f:
        f.attrs["keras_version"], f.attrs["backend"] = b"2.0.8-tf", b"tensorflow"
        root = f.create_group("model_weights")
        root.attrs["layer_names"] = np.array([n.encode() for n in names])
        for name in names:
            g = root.create_group(name)
            weights = groups.get(name, [])
            g.attrs["weight_names"] = np.array([w.encode() for w, _ in weights], dtype="S")
            for w, value in weights:
                g.create_dataset(w, data=value)
        f.create_group("optimizer_weights")


def lf_grid(angular: int, h: int, w: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).random((angular, angular, h, w), dtype=np.float32)


def as_views(grid: np.ndarray) -> torch.Tensor:
    a, _, h, w = grid.shape
    return torch.from_numpy(grid.reshape(1, a * a, h, w).copy())


@pytest.mark.parametrize(("numbers", "dup", "sep"), [((1, 2, 3, 4, 5, 6), 0, ""),
                                                      ((8, 9, 10, 11, 12, 13), 4, ""),
                                                      ((0, 1, 2, 3, 4, 5), 0, "_")])
def test_keras_checkpoint_converts_to_the_numpy_forward(tmp_path: Path, numbers, dup, sep, capsys, one_torch_thread):
    # numbers 8..11: the streams sort by creation number, not as text ('10' < '8'); 0: Keras's first 'sequential'
    seq = tuple(f"sequential_{n}" if n else "sequential" for n in numbers)
    arrays = keras_arrays(9, filters=3, depth=2, seed=1)
    src = tmp_path / "epinet.hdf5"
    write_keras_epinet(src, arrays, numbers, dup, sep)
    if numbers[0] == 0:  # Keras names its first Sequential model 'sequential'
        with h5py.File(src, "r+") as f:
            root = f["model_weights"]
            root.move("sequential_0", seq[0])
            root.attrs["layer_names"] = np.array([b"sequential" if n == b"sequential_0" else n
                                                  for n in root.attrs["layer_names"]])
    out = tmp_path / "epinet.pt"
    assert main(["convert-keras", str(src), str(out)]) == 0
    assert "9x9 views, 3 filters, 2 merged blocks" in capsys.readouterr().out
    net = get_trainable("epinet").load(out)
    assert net.config() == {"angular": 9, "filters": 3, "depth": 2}
    grid = lf_grid(9, 24, 27, seed=2)
    expected = np_epinet(grid, arrays)
    with torch.inference_mode():
        disparity, probability = net(as_views(grid))
    r = net.output_margin
    assert probability is None and disparity.shape == (1, 24, 27) and expected.shape == (24 - 2 * r, 27 - 2 * r)
    np.testing.assert_allclose(disparity[0, r:-r, r:-r].numpy(), expected, atol=1e-4, rtol=1e-4)


def test_the_border_is_the_edge_replication_of_the_network_output(one_torch_thread):
    torch.manual_seed(0)
    net = EPINet(angular=5, filters=2, depth=1).eval()
    views = torch.rand(2, 25, 17, 20)
    r = net.output_margin  # 3 + 1 + 1 = 5
    with torch.inference_mode():
        inner = net.valid(views)
        full, _ = net(views)
    assert r == 5 and inner.shape == (2, 7, 10) and full.shape == (2, 17, 20)
    expected = np.stack([np.pad(m, r, mode="edge") for m in inner.numpy()])
    np.testing.assert_array_equal(full.numpy(), expected)
    assert torch.equal(full[:, r:-r, r:-r], inner)
    assert torch.equal(full[:, 0, 0], inner[:, 0, 0]) and torch.equal(full[:, -1, 3], inner[:, -1, 0])
    with pytest.raises(ValueError, match="at least 11x11"):
        net(torch.rand(1, 25, 10, 30))


def test_tiles_equal_the_whole_image(one_torch_thread):
    torch.manual_seed(1)
    net = EPINet(angular=5, filters=2, depth=2).eval()
    trainable = get_trainable("epinet")
    views = torch.rand(1, 25, 41, 37)
    whole, _ = trainable.infer(net, views)
    timings: dict = {}
    tiled, _ = trainable.infer(net, views, tile=7, timings=timings)
    assert timings["tiles"] == 5 * 4  # the inner 29 x 25 px in tiles of 7: 5 x 4
    torch.testing.assert_close(tiled, whole, atol=1e-5, rtol=0)
    # the declared receptive radius (2R: a border pixel copies one R px inside) makes lfbench's generic
    # tiling, which keeps only each tile's own pixels of a full-size map, exact as well
    with torch.inference_mode():
        generic, _ = tiled_forward(net, views, 12, trainable.receptive_radius(net))
    torch.testing.assert_close(generic, whole, atol=1e-5, rtol=0)


def test_bf16_inference_follows_fp32(cpu_bf16, one_torch_thread):
    torch.manual_seed(2)
    net = EPINet(angular=5, filters=4, depth=1).eval()
    with torch.no_grad():  # a network whose output varies: larger BN gains than a fresh one's
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.weight.uniform_(1.0, 2.0)
    views = torch.rand(1, 25, 24, 24)
    trainable = get_trainable("epinet")
    fp32, _ = trainable.infer(net, views)
    bf16, _ = trainable.infer(net, views, precision="bf16")
    assert bf16.dtype == torch.float32
    spread = float(fp32.std())
    assert spread > 0 and float((bf16 - fp32).abs().max()) < 0.05 * spread + 1e-3


# -- refused checkpoints ------------------------------------------------------------------------------------


def _convert(args: list, capsys) -> tuple[int, str]:
    code = main(["convert-keras", *map(str, args)])
    return code, capsys.readouterr().err


def test_refused_checkpoints_are_one_line_naming_the_file(tmp_path: Path, capsys):
    arrays = keras_arrays(5, filters=2, depth=1, seed=3)
    src = tmp_path / "epinet5.hdf5"
    write_keras_epinet(src, arrays)
    out = tmp_path / "o.pt"
    cases = {
        "another angular size": ([src, out, "--angular", "9"],
                                 "an EPINET Keras checkpoint (5x5 views, 2 filters, 1 merged blocks), not 9x9 views"),
        "another network asked": ([src, out, "--network", "lfattnet"], "an EPINET Keras checkpoint, not lfattnet"),
        "a grid for a regression": ([src, out, "--interval", "1"], "EPINET regresses the disparity directly"),
    }
    truncated = tmp_path / "truncated.hdf5"
    truncated.write_bytes(src.read_bytes()[: src.stat().st_size // 2])
    cases["truncated"] = ([truncated, out], "truncated.hdf5")
    other = tmp_path / "dense.hdf5"
    with h5py.File(other, "w") as f:
        root = f.create_group("model_weights")
        root.attrs["layer_names"] = np.array([b"dense"])
        g = root.create_group("dense")
        g.attrs["weight_names"] = np.array([b"dense/kernel:0"])
        g.create_dataset("dense/kernel:0", data=np.zeros((3, 2), np.float32))
    cases["another network's file"] = ([other, out, "--network", "epinet"], "not an EPINET Keras checkpoint")
    missing = tmp_path / "no_last.hdf5"
    write_keras_epinet(missing, arrays)
    with h5py.File(missing, "r+") as f:
        f["model_weights/sequential_6"].attrs["weight_names"] = np.array([], dtype="S")
    cases["incomplete"] = ([missing, out], "not a complete EPINET Keras checkpoint")
    for what, (args, text) in cases.items():
        code, err = _convert(args, capsys)
        assert code == 2, what
        assert err.count("\n") == 1 and text in err and Path(args[0]).name in err, (what, err)
        assert not out.exists() and not list(tmp_path.glob(".o.pt*")), what


def test_weights_of_another_network_or_angular_size_are_refused(tmp_path: Path):
    from lfbench.training.checkpoint import export_weights

    path = tmp_path / "other.pt"
    export_weights(path, torch.nn.Linear(2, 2), method="subfocal", config={})
    with pytest.raises(DataError, match="subfocal") as info:
        get_trainable("epinet").load(path)
    assert "other.pt" in str(info.value) and "\n" not in str(info.value)
    five = tmp_path / "five.pt"
    export_weights(five, EPINet(angular=5, filters=2, depth=1), method="epinet")
    with pytest.raises(DataError, match="weights do not fit"):
        get_trainable("epinet").load(five, angular=9)


# -- training ---------------------------------------------------------------------------------------------


def test_the_loss_compares_the_inner_part_only():
    net = EPINet(angular=5, filters=2, depth=0)  # margin 4
    m = get_trainable("epinet").output_margin(net)
    disparity, target = torch.zeros(1, 11, 12), torch.zeros(1, 11, 12)
    target[:, :m] = 100.0  # a wrong border: not what the network computes
    d, p, t = crop_margin(disparity, None, target, m)
    assert m == 4 and d.shape == t.shape == (1, 3, 4) and p is None and float((d - t).abs().max()) == 0.0
    assert get_trainable("subfocal").output_margin(torch.nn.Linear(1, 1)) == 0


def test_a_patch_within_the_margin_is_refused(tmp_path: Path):
    from lfbench.training.config import TrainConfig
    from lfbench.training.model import build_model
    from lfbench.utils.errors import SpecError

    cfg = tmp_path / "c.toml"
    cfg.write_text('method = "epinet"\n[data]\nroots = ["/nowhere"]\npatch = 22\n[model]\nfilters = 1\n'
                   '[[stages]]\nloss = "l1"\nlr = 1e-4\nsteps = 1\n')
    with pytest.raises(SpecError, match="patch >= 23"):
        build_model(TrainConfig.from_toml(cfg))


def test_the_optimizer_is_the_authors_rmsprop(one_torch_thread):
    from types import SimpleNamespace

    net = EPINet(angular=5, filters=1, depth=0)
    stage = SimpleNamespace(name="s", lr=1e-4, steps=1, eps=1e-8, betas=(0.9, 0.999))
    opt = get_trainable("epinet").configure_optimizers(net, stage)
    assert isinstance(opt, torch.optim.RMSprop)
    group = opt.param_groups[0]
    assert group["lr"] == 1e-4 and group["alpha"] == 0.9 and group["eps"] == 1e-8 and group["momentum"] == 0


@pytest.mark.slow
def test_cpu_smoke_config_trains(tmp_path: Path):
    repo = Path(__file__).resolve().parents[1]
    out = tmp_path / "run"
    with contextlib.chdir(tmp_path):
        assert main(["-q", "train", str(repo / "configs" / "epinet_cpu_smoke.toml"), "--out", str(out)]) == 0
    net = get_trainable("epinet").load(out / "final.pt")
    assert net.config() == {"angular": 9, "filters": 4, "depth": 1}
    lines = (out / "metrics.jsonl").read_text().splitlines()
    assert any('"loss"' in line for line in lines)


def test_info_reports_the_parameters_and_the_flops(capsys):
    assert main(["info", "epinet"]) == 0
    out = capsys.readouterr().out
    assert "parameters: 5,118,681 (5,118,681 trainable)" in out
    # FLOPs by hand at 64 x 64: each 2x2 valid conv shrinks the map by 1 px; 2 FLOPs per multiply-add
    layers = 4 * ([(9, 70)] + [(70, 70)] * 5) + [(280, 280)] * 15 + [(280, 1)]
    sizes = 4 * list(range(63, 57, -1)) + list(range(57, 41, -1))
    expected = sum(2 * 4 * cin * cout * s * s for (cin, cout), s in zip(layers, sizes, strict=True))
    with torch.device("meta"):
        net = EPINet()
    assert get_trainable("epinet").flop_count(net, 64, 64)["total"] == expected
    assert "FLOPs of one forward pass at 512x512: 2,542 GFLOP" in out


@pytest.mark.slow
def test_check_plugin_passes():
    from lfbench.runs.plugin_check import check_plugin

    findings = check_plugin("epinet", {"angular": 9, "filters": 2, "depth": 1})
    status = {f.check: f.status for f in findings}
    assert status == {"build": "ok", "forward": "ok", "sign": "skip", "receptive_radius": "ok", "tiling": "ok",
                      "flops": "ok", "save/load": "ok", "training": "ok"}, [f.line() for f in findings]


def test_lfattnet_asked_by_name_gets_its_integer_grid(tmp_path: Path, capsys):
    from lfbench_methods.subfocal.network import SubFocalNet
    from test_keras_import import _randomise, write_keras_like

    src = tmp_path / "lfattnet.hdf5"
    write_keras_like(_randomise(SubFocalNet(width=2, interval=1.0), seed=3), src)
    out = tmp_path / "lfattnet.pt"
    assert main(["convert-keras", str(src), str(out), "--network", "lfattnet"]) == 0
    assert "9 disparities in [-4, 4] step 1" in capsys.readouterr().out
    code, err = _convert([src, tmp_path / "e.pt", "--network", "epinet"], capsys)
    assert code == 2 and "lfattnet.hdf5" in err and "not an EPINET Keras checkpoint" in err
