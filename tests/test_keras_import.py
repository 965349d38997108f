"""Keras checkpoint import: equivalence with the authors' model, name-independent mapping, refused files,
the convert-keras command and the torch checkpoint round trip."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from conftest import require
from lfbench_methods.subfocal.keras_import import (
    build_from_checkpoint,
    load_checkpoint,
    load_keras_checkpoint,
    save_checkpoint,
)
from lfbench_methods.subfocal.network import SubFocalNet, count_trainable

from lfbench.cli import main
from lfbench.utils.errors import DataError

pytestmark = pytest.mark.usefixtures("one_torch_thread")  # small tensors: see conftest


@pytest.fixture(scope="module")
def reference(shared_data: Path) -> Path:
    return require(shared_data / "reference" / "subfocal_keras_64")


@pytest.mark.slow
def test_reproduces_the_keras_reference_disparity(reference: Path, tmp_path: Path):
    out = tmp_path / "paper.pt"
    assert main(["convert-keras", str(reference / "model.hdf5"), str(out)]) == 0
    net = build_from_checkpoint(out)
    assert count_trainable(net) == 5_055_329
    views = np.load(reference / "views.npy")  # (64, 64, 81), channel k = view k
    expected = np.load(reference / "disparity.npy")
    with torch.inference_mode():
        disp, prob = net(torch.from_numpy(views).permute(2, 0, 1)[None])
    err = np.abs(disp[0].numpy() - expected)
    assert err.max() < 1e-3, f"max |ours - keras| = {err.max():.2e} px"
    assert prob.shape == (1, 17, 64, 64)
    # the file was converted, not re-read: the checkpoint equals a direct import
    direct = load_keras_checkpoint(reference / "model.hdf5").state_dict()
    for key, value in net.state_dict().items():
        assert torch.equal(value, direct[key]), key


# -- a Keras-layout file written from one of our networks, with other creation counters ------------

def _keras_order(net: SubFocalNet):
    """(convs, bns) of the extractor and of the top level in the Keras code's creation order, per the fact
    sheet: stem, layers 1-4 (projection before the block's convs), SPP pool 2/4/8/16, last convbn, 1x1."""
    ex = net.extractor
    cbs = [ex.stem1, ex.stem2]
    for layer in (ex.layer1, ex.layer2, ex.layer3, ex.layer4):
        for blk in layer.blocks:
            cbs += ([blk.downsample] if blk.downsample is not None else []) + [blk.conv1, blk.conv2]
    cbs += [b.convbn for b in ex.spp] + [ex.last]
    ag = net.aggregation
    vcbs = [ag.dres0a, ag.dres0b, ag.dres1a, ag.dres1b, ag.dres4a, ag.dres4b, ag.classify]
    return ([c.conv for c in cbs] + [ex.out], [c.bn for c in cbs],
            [c.conv for c in vcbs] + [ag.out], [c.bn for c in vcbs])


def _keras_kernel(weight: torch.Tensor) -> np.ndarray:
    w = weight.detach().numpy()
    if w.ndim == 2:  # Linear (out, in) -> Conv3D (1, 1, 1, in, out)
        return w.T.reshape(1, 1, 1, *w.T.shape)
    return np.transpose(w, (*range(2, w.ndim), 1, 0))


def write_keras_like(net: SubFocalNet, path: Path, offset: int = 7) -> None:
    """An HDF5 file in the layout of Keras ``model.save`` (model_weights/, layer_names, nested model)."""
    convs, bns, vconvs, vbns = _keras_order(net)
    nb = len(bns)

    def layer(group, name: str, arrays: dict) -> None:
        g = group.create_group(name)
        g.attrs["weight_names"] = np.array([f"{name}/{k}:0".encode() for k in arrays], dtype=object)
        sub = g.create_group(name)
        for k, v in arrays.items():
            sub.create_dataset(f"{k}:0", data=np.asarray(v, dtype=np.float32))

    def bn_arrays(bn) -> dict:
        return {"gamma": bn.weight.detach().numpy(), "beta": bn.bias.detach().numpy(),
                "moving_mean": bn.running_mean.numpy(), "moving_variance": bn.running_var.numpy()}

    def cname(kind: str, i: int) -> str:
        i += offset
        return kind if i == 0 else f"{kind}_{i}"

    with h5py.File(path, "w") as f:
        root = f.create_group("model_weights")
        f.create_group("optimizer_weights")
        names = [f"input_{i + 1}" for i in range(81)] + [f"model_{offset}"]
        for name in names[:81]:
            root.create_group(name).attrs["weight_names"] = np.array([], dtype=np.float64)
        model = root.create_group(f"model_{offset}")
        for i, conv in enumerate(convs):
            layer(model, cname("conv2d", i), {"kernel": _keras_kernel(conv.weight)})
        for i, bn in enumerate(bns):
            layer(model, cname("batch_normalization", i), bn_arrays(bn))
        k = 0
        if net.attention is not None:
            for fc in (net.attention.fc1, net.attention.fc2):
                layer(root, cname("conv3d", k), {"kernel": _keras_kernel(fc.weight), "bias": fc.bias.detach().numpy()})
                names.append(cname("conv3d", k))
                k += 1
        for conv in vconvs:
            layer(root, cname("conv3d", k), {"kernel": _keras_kernel(conv.weight)})
            names.append(cname("conv3d", k))
            k += 1
        for i, bn in enumerate(vbns):
            layer(root, cname("batch_normalization", nb + i), bn_arrays(bn))
            names.append(cname("batch_normalization", nb + i))
        for extra in ("lambda_4", "multiply", "activation_3"):
            root.create_group(extra).attrs["weight_names"] = np.array([], dtype=np.float64)
            names.append(extra)
        root.attrs["layer_names"] = np.array([n.encode() for n in names], dtype=object)


def _randomise(net: SubFocalNet, seed: int) -> SubFocalNet:
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, t in list(net.named_parameters()) + list(net.named_buffers()):
            if name.endswith("running_var"):
                t.copy_(torch.rand(t.shape, generator=g) + 0.5)
            elif t.dtype.is_floating_point and "running" in name or name in dict(net.named_parameters()):
                t.copy_((torch.rand(t.shape, generator=g) - 0.5) * 0.4)
    return net.eval()


@pytest.mark.parametrize("attention,offset", [(True, 0), (False, 93)])
def test_layers_map_by_creation_order_not_by_name(tmp_path: Path, attention: bool, offset: int):
    # offset 93 makes conv2d_100.. sort before conv2d_99 as text: the import must sort numerically.
    net = _randomise(SubFocalNet(width=3, attention=attention, interval=1.0), seed=offset)
    path = tmp_path / "ckpt.hdf5"
    write_keras_like(net, path, offset=offset)
    loaded = load_keras_checkpoint(path, interval=1.0)
    assert loaded.config() == net.config()
    for key, value in net.state_dict().items():
        assert torch.equal(value, loaded.state_dict()[key]), key


def test_refuses_files_that_are_not_keras_checkpoints(tmp_path: Path):
    text = tmp_path / "notes.hdf5"
    text.write_text("hello\n")
    with pytest.raises(DataError, match="not an HDF5 file"):
        load_keras_checkpoint(text)
    plain = tmp_path / "plain.h5"
    with h5py.File(plain, "w") as f:
        f.create_dataset("x", data=np.zeros(3))
    with pytest.raises(DataError, match="not a Keras checkpoint"):
        load_keras_checkpoint(plain)
    other = tmp_path / "dense.h5"
    with h5py.File(other, "w") as f:
        root = f.create_group("model_weights")
        root.attrs["layer_names"] = np.array([b"dense"], dtype=object)
        root.create_group("dense").create_group("dense").create_dataset("kernel:0", data=np.zeros((3, 2)))
    with pytest.raises(DataError, match="not a SubFocal"):
        load_keras_checkpoint(other)
    with pytest.raises(DataError, match="not found"):
        load_keras_checkpoint(tmp_path / "missing.hdf5")
    for err in (str(e) for e in [DataError("x\ny", text)]):
        assert "\n" not in err


def test_convert_keras_cli_refuses_with_one_line_and_writes_nothing(tmp_path: Path, capsys):
    bad = tmp_path / "bad.hdf5"
    bad.write_bytes(b"\x89HDF-not-really")
    out = tmp_path / "out.pt"
    assert main(["convert-keras", str(bad), str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.hdf5" in err
    assert not out.exists() and not list(tmp_path.glob(".out.pt*"))


def test_convert_keras_cli_round_trip(tmp_path: Path):
    net = _randomise(SubFocalNet(width=2, interval=1.0), seed=3)
    src = tmp_path / "lfattnet.hdf5"
    write_keras_like(net, src, offset=12)
    out = tmp_path / "w" / "lfattnet.pt"
    assert main(["convert-keras", str(src), str(out), "--interval", "1"]) == 0
    raw = torch.load(out, weights_only=True)
    assert set(raw) == {"format", "method", "state_dict", "config", "source"} and raw["source"] == "keras:lfattnet.hdf5"
    assert raw["method"] == "subfocal" and raw["format"] == "lfbench.weights"  # it names the network it holds
    assert raw["config"]["interval"] == 1.0 and raw["config"]["width"] == 2
    rebuilt = build_from_checkpoint(out)
    for key, value in net.state_dict().items():
        assert torch.equal(value, rebuilt.state_dict()[key]), key


def test_torch_checkpoint_save_load_round_trip_and_refusals(tmp_path: Path):
    net = _randomise(SubFocalNet(width=2, interval=0.25, interpolation="phase", attention=False), seed=5)
    path = tmp_path / "net.pt"
    save_checkpoint(net, path, source="test")
    state, config, source = load_checkpoint(path)
    assert config == net.config() and source == "test"
    again = build_from_checkpoint(path)
    x = torch.rand(1, 81, 8, 8)
    with torch.inference_mode():
        assert torch.equal(net(x)[0], again(x)[0])
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a zip file at all")
    with pytest.raises(DataError, match="not a torch checkpoint"):
        load_checkpoint(junk)
    listed = tmp_path / "list.pt"
    torch.save([1, 2, 3], listed)
    with pytest.raises(DataError, match="list.pt: a torch file holding a list, not an lfbench weights file"):
        load_checkpoint(listed)
    wrong = tmp_path / "wrong.pt"
    torch.save({"state_dict": state, "config": {**config, "width": 3}}, wrong)
    with pytest.raises(DataError, match="do not fit"):
        build_from_checkpoint(wrong)
