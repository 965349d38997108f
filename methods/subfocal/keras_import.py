"""Import the authors' Keras checkpoints (``model.save`` HDF5) into :class:`SubFocalNet`.

The file's ``model_weights/`` group lists its layers in the attribute ``layer_names``; the shared
feature extractor is a nested model group holding its own layers. Keras names layers with
per-process creation counters (``conv2d_7``, ``batch_normalization_12``), so names differ between
files: layers are matched by creation order (the counter suffix) and checked by shape.

Keras kernel layouts: Conv2D (kh, kw, in, out) -> (out, in, kh, kw); Conv3D (kd, kh, kw, in, out)
-> (out, in, kd, kh, kw); Dense-like 1x1x1 Conv3D (1, 1, 1, in, out) -> Linear (out, in).
BatchNorm gamma, beta, moving_mean, moving_variance -> weight, bias, running_mean, running_var
(eps 1e-3 and momentum 0.99 <-> 0.01 are fixed by the network's construction).
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import torch
from lfbench_methods.keras_hdf5 import read_hdf5
from lfbench_methods.subfocal.network import SubFocalNet, count_trainable
from torch import nn

from lfbench.utils.atomic import write_bytes
from lfbench.utils.errors import DataError

_SUFFIX = re.compile(r"^(?P<base>.*?)(?:_(?P<n>\d+))?$")


def _order_key(name: str) -> int:
    """Creation order from a Keras layer name: conv2d -> 0, conv2d_7 -> 7."""
    m = _SUFFIX.match(name)
    return int(m.group("n")) if m and m.group("n") else 0


def _base(name: str) -> str:
    m = _SUFFIX.match(name)
    return m.group("base") if m else name


def _decode(v) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


MAX_KERAS_BYTES = 2 * 1024**3  # all weight arrays of one checkpoint together (the paper model: ~20 MB)


def _links(group, path: Path) -> list[tuple[str, object]]:
    """(name, object) of a group's members, refusing links that are not hard links: an external link
    would make h5py open another file (anything on disk), a soft link may dangle or loop."""
    import h5py

    out = []
    for name in group.keys():
        link = group.get(name, getlink=True)
        if isinstance(link, h5py.ExternalLink):
            raise DataError(f"HDF5 member {group.name}/{name} is an external link to another file (not allowed)", path)
        if isinstance(link, h5py.SoftLink):
            raise DataError(f"HDF5 member {group.name}/{name} is a soft link (not allowed in a checkpoint)", path)
        out.append((name, group[name]))
    return out


def _layer_arrays(group, path: Path, budget: list[int]) -> dict[str, np.ndarray]:
    """{'kernel': ..., 'gamma': ...} of one layer group (weights sit in a sub-group of the same name),
    following hard links only; every array's size is checked against ``budget`` (bytes left) before
    it is read."""
    import h5py

    out: dict[str, np.ndarray] = {}
    pending = [group]
    while pending:
        for name, obj in _links(pending.pop(), path):
            if isinstance(obj, h5py.Group):
                pending.append(obj)
            elif isinstance(obj, h5py.Dataset):
                if obj.dtype.kind not in "fiu":
                    raise DataError(f"HDF5 dataset {obj.name} holds {obj.dtype}, not numbers", path)
                nbytes = int(obj.size) * 4
                budget[0] -= nbytes
                if budget[0] < 0:
                    raise DataError(f"the weight arrays are larger than a SubFocal checkpoint can be "
                                    f"({MAX_KERAS_BYTES // 1024**2} MiB)", path)
                out[name.split(":")[0]] = np.asarray(obj[()], dtype=np.float32)
    return out


def read_keras_layers(path: Path) -> tuple[list[tuple[str, dict]], list[tuple[str, dict]]]:
    """Read an HDF5 checkpoint: (top-level layers, nested-model layers), each a list of
    (name, {weight name: array}) for layers that hold weights, in file order of ``layer_names``."""
    return read_hdf5(path, _read_layers, "a Keras checkpoint of the expected structure")


def _read_layers(f, path: Path) -> tuple[list[tuple[str, dict]], list[tuple[str, dict]]]:
    import h5py

    budget = [MAX_KERAS_BYTES]
    members = dict(_links(f, path))
    root = members["model_weights"] if "model_weights" in members else f
    if not isinstance(root, h5py.Group) or "layer_names" not in root.attrs:
        raise DataError("not a Keras checkpoint (no model_weights/ with a layer_names attribute)", path)
    layers = dict(_links(root, path))
    top: list[tuple[str, dict]] = []
    nested: list[tuple[str, dict]] = []
    for raw in np.atleast_1d(root.attrs["layer_names"]):
        name = _decode(raw)
        if name not in layers:  # a layer without weights may have no group
            continue
        g = layers[name]
        if not isinstance(g, h5py.Group):
            raise DataError(f"layer {name[:60]!r} is not an HDF5 group", path)
        children = _links(g, path)
        if any(k != name and isinstance(obj, h5py.Group) for k, obj in children):  # a nested model
            if nested:
                raise DataError("Keras checkpoint has more than one nested model; not a SubFocal model", path)
            nested = [(k, _layer_arrays(obj, path, budget)) for k, obj in children if isinstance(obj, h5py.Group)]
            continue
        arrays = _layer_arrays(g, path, budget)
        if arrays:
            top.append((name, arrays))
    return top, nested


def _by_kind(layers: list[tuple[str, dict]], kind: str) -> list[tuple[str, dict]]:
    """Layers whose base name is ``kind`` (conv2d, conv3d, batch_normalization), in creation order."""
    chosen = [(n, a) for n, a in layers if _base(n) == kind or n == kind]
    return sorted(chosen, key=lambda item: _order_key(item[0]))


def _keras_extractor_order(net: SubFocalNet) -> tuple[list[nn.Conv2d], list[nn.BatchNorm2d]]:
    """The extractor's conv and BN layers in the order the Keras code creates them."""
    ex = net.extractor
    convbns = [ex.stem1, ex.stem2]
    for layer in (ex.layer1, ex.layer2, ex.layer3, ex.layer4):
        for block in layer.blocks:
            if block.downsample is not None:
                convbns.append(block.downsample)
            convbns += [block.conv1, block.conv2]
    convbns += [branch.convbn for branch in ex.spp]  # pool 2, 4, 8, 16
    convbns.append(ex.last)
    return [c.conv for c in convbns] + [ex.out], [c.bn for c in convbns]


def _keras_volume_order(net: SubFocalNet) -> tuple[list[nn.Conv3d], list[nn.BatchNorm3d]]:
    ag = net.aggregation
    cbs = [ag.dres0a, ag.dres0b, ag.dres1a, ag.dres1b, ag.dres4a, ag.dres4b, ag.classify]
    return [c.conv for c in cbs] + [ag.out], [c.bn for c in cbs]


def _put(param: torch.Tensor, value: np.ndarray, what: str, path: Path) -> None:
    if tuple(param.shape) != value.shape:
        raise DataError(f"{what}: shape {value.shape} does not fit the network's {tuple(param.shape)}", path)
    with torch.no_grad():
        param.copy_(torch.from_numpy(np.ascontiguousarray(value)))


def _load_convs(convs: list[nn.Module], layers: list[tuple[str, dict]], path: Path, where: str) -> None:
    if len(layers) != len(convs):
        raise DataError(f"{where}: {len(layers)} convolution layers, the network has {len(convs)}", path)
    for module, (name, arrays) in zip(convs, layers, strict=True):
        if "kernel" not in arrays:
            raise DataError(f"layer {name!r} has no kernel", path)
        k = arrays["kernel"]
        k = np.transpose(k, (k.ndim - 1, k.ndim - 2, *range(k.ndim - 2)))  # (..., in, out) -> (out, in, ...)
        if isinstance(module, nn.Linear):
            k = k.reshape(k.shape[0], k.shape[1])
        _put(module.weight, k, f"layer {name!r} kernel", path)
        if module.bias is not None:
            if "bias" not in arrays:
                raise DataError(f"layer {name!r} has no bias", path)
            _put(module.bias, arrays["bias"], f"layer {name!r} bias", path)
        elif "bias" in arrays:
            raise DataError(f"layer {name!r} has a bias the network does not have", path)


def _load_bns(bns: list[nn.Module], layers: list[tuple[str, dict]], path: Path, where: str) -> None:
    if len(layers) != len(bns):
        raise DataError(f"{where}: {len(layers)} BatchNormalization layers, the network has {len(bns)}", path)
    for module, (name, arrays) in zip(bns, layers, strict=True):
        for keras_key, attr in (("gamma", "weight"), ("beta", "bias"), ("moving_mean", "running_mean"),
                                ("moving_variance", "running_var")):
            if keras_key not in arrays:
                raise DataError(f"layer {name!r} has no {keras_key}", path)
            _put(getattr(module, attr), arrays[keras_key], f"layer {name!r} {keras_key}", path)


def infer_config(top: list[tuple[str, dict]], nested: list[tuple[str, dict]], path: Path,
                 interval: float, d_min: float, d_max: float) -> dict:
    """Network configuration from the weights' shapes (width, attention, angular); the disparity
    grid is not stored in the weights and comes from the arguments."""
    convs3d = _by_kind(top, "conv3d")
    agg = [a for _, a in convs3d if a["kernel"].shape[:3] == (3, 3, 3)]
    att = [a for _, a in convs3d if a["kernel"].shape[:3] == (1, 1, 1)]
    if not nested or len(agg) != 8:
        raise DataError("not a SubFocal/LFattNet Keras checkpoint (expected a nested feature extractor and "
                        f"eight 3x3x3 Conv3D layers, found {len(agg)})", path)
    cin, width = agg[0]["kernel"].shape[3:]
    angular = int(round(np.sqrt(cin / 4)))
    if angular * angular * 4 != cin:
        raise DataError(f"first Conv3D has {cin} input channels, not 4 x a square number of views", path)
    return {"d_min": d_min, "d_max": d_max, "interval": interval, "interpolation": "bilinear",
            "width": int(width), "attention": bool(att), "angular": angular}


def load_keras_checkpoint(path: str | Path, interval: float = 0.5, d_min: float = -4.0,
                          d_max: float = 4.0) -> SubFocalNet:
    """A SubFocalNet (eval mode) holding the weights of a Keras HDF5 checkpoint.

    interval, d_min, d_max: the disparity grid the model was trained with (SubFocal: 0.5,
    LFattNet: 1); it is not recorded in the weights. DataError for anything else than such a file.
    """
    path = Path(path)
    top, nested = read_keras_layers(path)
    try:
        return _build_keras(top, nested, path, interval, d_min, d_max)
    except (KeyError, ValueError, IndexError, TypeError) as exc:  # a layer without a kernel, a 2-D Conv3D ...
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise DataError(f"not a SubFocal/LFattNet Keras checkpoint ({reason})", path) from None


def _build_keras(top: list[tuple[str, dict]], nested: list[tuple[str, dict]], path: Path, interval: float,
                 d_min: float, d_max: float) -> SubFocalNet:
    config = infer_config(top, nested, path, interval, d_min, d_max)
    net = SubFocalNet(**config)  # width and angular checked against their bounds before allocating
    convs, bns = _keras_extractor_order(net)
    _load_convs(convs, _by_kind(nested, "conv2d"), path, "feature extractor")
    _load_bns(bns, _by_kind(nested, "batch_normalization"), path, "feature extractor")
    convs3d = _by_kind(top, "conv3d")
    att = [item for item in convs3d if item[1]["kernel"].shape[:3] == (1, 1, 1)]
    agg = [item for item in convs3d if item[1]["kernel"].shape[:3] != (1, 1, 1)]
    if net.attention is not None:
        _load_convs([net.attention.fc1, net.attention.fc2], att, path, "channel attention")
    vconvs, vbns = _keras_volume_order(net)
    _load_convs(vconvs, agg, path, "3D aggregation")
    _load_bns(vbns, _by_kind(top, "batch_normalization"), path, "3D aggregation")
    extra = {_base(n) for n, _ in top} - {"conv3d", "batch_normalization"}
    if extra:
        raise DataError(f"unexpected weight layers {sorted(extra)}; not a SubFocal/LFattNet checkpoint", path)
    return net.eval()


def save_checkpoint(net: SubFocalNet, out: str | Path, source: str) -> None:
    """Write ``{"format", "method", "state_dict", "config", "source"}`` atomically with torch.save."""
    from lfbench.method.checkpoint import WEIGHTS_FORMAT

    buf = io.BytesIO()
    torch.save({"format": WEIGHTS_FORMAT, "method": "subfocal", "state_dict": net.state_dict(),
                "config": net.config(), "source": source}, buf)
    write_bytes(out, buf.getvalue())


def load_checkpoint(path: str | Path, network: str | None = None) -> tuple[dict, dict, str]:
    """(state_dict, config, source) of a weights file written by :func:`save_checkpoint` or training, read by
    lfbench's one checkpoint reader (``torch.load(weights_only=True)``); DataError naming the file otherwise,
    also for the weights of another network than ``network`` (``a tinycnn checkpoint, not subfocal``)."""
    from lfbench.method.checkpoint import read_weights

    payload = read_weights(path, network, tuple(n for n in ("subfocal", "lfattnet") if n != network))
    return payload["state_dict"], payload["config"], str(payload.get("source", ""))


def build_from_checkpoint(path: str | Path, network: str | None = None, **overrides) -> SubFocalNet:
    """A SubFocalNet (eval mode) from a weights file; ``overrides`` replace config entries that do not change
    the weights' shapes (the caller checks conflicts); ``network``: as in :func:`load_checkpoint`."""
    from lfbench.method.trainable import network_from_state

    state, config, _ = load_checkpoint(path, network)
    return network_from_state(SubFocalNet, state, {**config, **overrides}, path)


__all__ = ["load_keras_checkpoint", "read_keras_layers", "save_checkpoint", "load_checkpoint",
           "build_from_checkpoint", "count_trainable"]
