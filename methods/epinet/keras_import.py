"""Import the EPINET authors' Keras checkpoints (``model.save`` / ``save_weights`` HDF5 of
chshin10/epinet's ``define_epinet``) into :class:`EPINet`.

Layout (Keras 2): ``model_weights/`` (or the file's root) lists its layers in the attribute ``layer_names``;
the four streams, the merged blocks and the last layers are nested Sequential models, each a group whose
attribute ``weight_names`` lists its arrays as ``<layer>/<weight>:0`` (datasets at that path in the group).
The authors' layer names: streams ``S1_c1<i>``, ``S1_c2<i>``, ``S1_BN<i>`` (i = 0..2), merged blocks
``S2_c1<i>``, ``S2_c2<i>``, ``S2_BN<i>`` (i = 0..depth-1), last ``S3_c10`` and ``S3_last``. TensorFlow
appends ``_<n>`` to a layer name made again in the same session (``S1_c10_1``: the second stream) and
Keras numbers the Sequential models by creation (``sequential_1`` .. ``sequential_6``, or other numbers
in another session): the streams are ordered by that number, which is the order define_epinet makes them
(90d, 0d, 45d, m45d), and every array is checked by shape.

Keras Conv2D kernel (kh, kw, in, out) -> (out, in, kh, kw); BatchNormalization gamma, beta, moving_mean,
moving_variance -> weight, bias, running_mean, running_var.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import torch
from lfbench_methods.epinet.network import STREAM_BLOCKS
from lfbench_methods.keras_hdf5 import open_hdf5, read_hdf5

from lfbench.utils.errors import DataError

MAX_KERAS_BYTES = 2 * 1024**3  # all weight arrays together (the paper network: ~20 MB)
_LAYER = re.compile(r"^S(?P<stage>[123])_(?P<kind>c1|c2|BN|last)_?(?P<index>\d*?)(?:_\d+)?$")
_SUFFIX = re.compile(r"_(\d+)$")
_BN_KEYS = (("gamma", "weight"), ("beta", "bias"), ("moving_mean", "running_mean"),
            ("moving_variance", "running_var"))
WHAT = "EPINET Keras checkpoint"


def _decode(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _hard(group, name: str, path: Path):
    """``group[name]`` following hard links only (an external link would open another file)."""
    import h5py

    obj = group
    for part in name.split("/"):
        link = obj.get(part, getlink=True)
        if link is None:
            raise DataError(f"HDF5 member {obj.name}/{part} is missing", path)
        if not isinstance(link, h5py.HardLink):
            raise DataError(f"HDF5 member {obj.name}/{part} is a soft or external link (not allowed in a checkpoint)",
                            path)
        obj = obj[part]
    return obj


def _weight_names(group) -> list[str]:
    return [_decode(n) for n in np.atleast_1d(group.attrs.get("weight_names", []))]


def _root(f, path: Path):
    import h5py

    root = _hard(f, "model_weights", path) if "model_weights" in f else f
    if not isinstance(root, h5py.Group) or "layer_names" not in root.attrs:
        raise DataError("not a Keras checkpoint (no model_weights/ with a layer_names attribute)", path)
    return root


def _layer_of(weight_name: str) -> tuple[str, str]:
    """'S1_c10_1/kernel:0' -> ('S1_c10_1', 'kernel')."""
    parts = weight_name.split("/")
    return (parts[-2] if len(parts) > 1 else ""), parts[-1].split(":")[0]


def holds_epinet(path: str | Path) -> bool:
    """Whether a Keras HDF5 checkpoint holds EPINET's layers (weights named S1_/S2_/S3_...); False for
    anything else, unreadable files included (the other importers then say what is wrong)."""
    try:
        with open_hdf5(Path(path)) as f:
            root = _root(f, Path(path))
            for raw in np.atleast_1d(root.attrs["layer_names"]):
                name = _decode(raw)
                link = root.get(name, getlink=True)
                if link is None or type(link).__name__ != "HardLink":
                    continue
                if any(_LAYER.match(_layer_of(w)[0]) for w in _weight_names(root[name])):
                    return True
    except (DataError, OSError, KeyError, TypeError, ValueError, AttributeError, RuntimeError):
        return False
    return False


def read_epinet_layers(path: str | Path) -> list[tuple[str, dict[str, dict[str, np.ndarray]]]]:
    """The layer groups of an EPINET checkpoint that hold weights: [(group name, {layer name: {weight:
    array}})] in the file's order; DataError naming the file for anything unreadable."""
    return read_hdf5(Path(path), _read, f"a readable {WHAT}")


def _read(f, path: Path) -> list[tuple[str, dict[str, dict[str, np.ndarray]]]]:
    import h5py

    root = _root(f, path)
    budget = MAX_KERAS_BYTES
    out = []
    for raw in np.atleast_1d(root.attrs["layer_names"]):
        name = _decode(raw)
        if name not in root:
            continue
        group = _hard(root, name, path)
        if not isinstance(group, h5py.Group):
            raise DataError(f"layer {name[:60]!r} is not an HDF5 group", path)
        layers: dict[str, dict[str, np.ndarray]] = {}
        for weight in _weight_names(group):
            data = _hard(group, weight, path)
            if not isinstance(data, h5py.Dataset) or data.dtype.kind != "f":
                raise DataError(f"HDF5 member {group.name}/{weight[:60]} is not an array of floats", path)
            budget -= int(data.size) * 4
            if budget < 0:
                raise DataError(f"the weight arrays are larger than an EPINET checkpoint can be "
                                f"({MAX_KERAS_BYTES // 1024**2} MiB)", path)
            layer, key = _layer_of(weight)
            layers.setdefault(layer, {})[key] = np.asarray(data[()], dtype=np.float32)
        if layers:
            out.append((name, layers))
    return out


def _creation(name: str) -> int:
    m = _SUFFIX.search(name)
    return int(m.group(1)) if m else 0


def _blocks(group: str, layers: dict[str, dict[str, np.ndarray]], stage: str, path: Path
            ) -> list[dict[str, dict[str, np.ndarray]]]:
    """A stream's or the merged part's blocks [{'c1': arrays, 'c2': arrays, 'BN': arrays}] by block index."""
    blocks: dict[int, dict[str, dict[str, np.ndarray]]] = {}
    for layer, arrays in layers.items():
        m = _LAYER.match(layer)
        if not m or m.group("stage") != stage or m.group("kind") == "last" or not m.group("index"):
            raise DataError(f"{group}: layer {layer[:60]!r} is not an S{stage} block layer of EPINET", path)
        kinds = blocks.setdefault(int(m.group("index")), {})
        if m.group("kind") in kinds:
            raise DataError(f"{group}: block {m.group('index')} has two {m.group('kind')} layers", path)
        kinds[m.group("kind")] = arrays
    if sorted(blocks) != list(range(len(blocks))) or any(set(b) != {"c1", "c2", "BN"} for b in blocks.values()):
        raise DataError(f"{group}: the S{stage} blocks are not numbered 0..n-1 with c1, c2 and BN each", path)
    return [blocks[i] for i in range(len(blocks))]


def parse_layout(groups: list[tuple[str, dict]], path: Path) -> dict:
    """{'streams': [4 x blocks], 'merged': blocks, 'last': {'c1': arrays, 'last': arrays}, 'config': {...}}
    from the layer groups; DataError naming what the file holds when it is not EPINET's layout."""
    stages: dict[str, list[tuple[str, dict]]] = {"1": [], "2": [], "3": []}
    for name, layers in groups:
        found = {m.group("stage") for m in map(_LAYER.match, layers) if m}
        if len(found) != 1 or len(layers) != sum(1 for n in layers if _LAYER.match(n)):
            raise DataError(f"not an {WHAT}: layer group {name[:60]!r} holds {', '.join(sorted(layers))[:120]}", path)
        stages[found.pop()].append((name, layers))
    if len(stages["1"]) != 4 or len(stages["2"]) > 1 or len(stages["3"]) != 1:
        raise DataError(f"not a complete {WHAT}: {len(stages['1'])} stream groups (4 needed), {len(stages['2'])} "
                        f"merged and {len(stages['3'])} last groups", path)
    streams = [_blocks(n, layers, "1", path) for n, layers in sorted(stages["1"], key=lambda g: _creation(g[0]))]
    merged = _blocks(*stages["2"][0], "2", path) if stages["2"] else []
    last_name, last_layers = stages["3"][0]
    last = {}
    for layer, arrays in last_layers.items():
        m = _LAYER.match(layer)
        kind = "last" if m and m.group("kind") == "last" else "c1" if m and m.group("kind") == "c1" else None
        if kind is None or kind in last:
            raise DataError(f"{last_name}: unexpected layer {layer[:60]!r} among EPINET's last layers", path)
        last[kind] = arrays
    if set(last) != {"c1", "last"}:
        raise DataError(f"{last_name}: EPINET's last layers S3_c10 and S3_last are not both there", path)
    try:
        angular, filters = (int(n) for n in streams[0][0]["c1"]["kernel"].shape[2:])
    except (KeyError, ValueError) as exc:
        raise DataError(f"the first stream convolution has no 2x2 kernel of (in, out) channels ({exc})", path) \
            from None
    if any(len(blocks) != STREAM_BLOCKS for blocks in streams):
        raise DataError(f"an {WHAT} has {STREAM_BLOCKS} blocks per stream, this file "
                        f"{', '.join(str(len(b)) for b in streams)}", path)
    return {"streams": streams, "merged": merged, "last": last,
            "config": {"angular": angular, "filters": filters, "depth": len(merged)}}


def describe(config: dict) -> str:
    """'an EPINET Keras checkpoint (9x9 views, 70 filters, 7 merged blocks)'."""
    a = config["angular"]
    return f"an {WHAT} ({a}x{a} views, {config['filters']} filters, {config['depth']} merged blocks)"


def _put(param: torch.Tensor, value: np.ndarray, what: str, path: Path) -> None:
    if value.ndim == 4:  # Keras (kh, kw, in, out) -> PyTorch (out, in, kh, kw)
        value = np.transpose(value, (3, 2, 0, 1))
    if tuple(param.shape) != value.shape:
        raise DataError(f"{what}: shape {value.shape} does not fit the network's {tuple(param.shape)}", path)
    with torch.no_grad():
        param.copy_(torch.from_numpy(np.ascontiguousarray(value)))


def _load_conv(conv: torch.nn.Conv2d, arrays: dict[str, np.ndarray], what: str, path: Path) -> None:
    for key in ("kernel", "bias"):
        if key not in arrays:
            raise DataError(f"{what} has no {key}", path)
    _put(conv.weight, arrays["kernel"], f"{what} kernel", path)
    _put(conv.bias, arrays["bias"], f"{what} bias", path)


def _load_block(block, arrays: dict[str, dict[str, np.ndarray]], what: str, path: Path) -> None:
    _load_conv(block.conv1, arrays["c1"], f"{what} first conv", path)
    _load_conv(block.conv2, arrays["c2"], f"{what} second conv", path)
    for keras_key, attr in _BN_KEYS:
        if keras_key not in arrays["BN"]:
            raise DataError(f"{what} BN has no {keras_key}", path)
        _put(getattr(block.bn, attr), arrays["BN"][keras_key], f"{what} BN {keras_key}", path)


def load_keras_epinet(path: str | Path, angular: int | None = None):
    """An EPINet (eval mode) holding the weights of the authors' Keras checkpoint; ``angular``: the views per
    row the caller needs (None: the file's). DataError naming the file and what it holds otherwise."""
    from lfbench_methods.epinet.network import EPINet, check_config

    path = Path(path)
    layout = parse_layout(read_epinet_layers(path), path)
    config = layout["config"]
    if angular is not None and angular != config["angular"]:
        raise DataError(f"{describe(config)}, not {angular}x{angular} views", path)
    try:
        check_config(**config)
    except ValueError as exc:
        raise DataError(f"{describe(config)} that lfbench cannot build: {exc}", path) from None
    net = EPINet(**config)
    for s, (stream, blocks) in enumerate(zip(net.streams, layout["streams"], strict=True)):
        for i, (block, arrays) in enumerate(zip(stream, blocks, strict=True)):
            _load_block(block, arrays, f"stream {s + 1} block {i}", path)
    for i, (block, arrays) in enumerate(zip(net.merged, layout["merged"], strict=True)):
        _load_block(block, arrays, f"merged block {i}", path)
    _load_conv(net.last1, layout["last"]["c1"], "S3_c10", path)
    _load_conv(net.last2, layout["last"]["last"], "S3_last", path)
    return net.eval()


__all__ = ["load_keras_epinet", "holds_epinet", "read_epinet_layers", "parse_layout", "describe"]
