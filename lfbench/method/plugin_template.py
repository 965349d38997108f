"""``lfbench new-plugin NAME --out DIR``: a plugin package that ``pip install DIR`` installs and that passes
``lfbench check-plugin NAME``: a pyproject with the entry point, the plugin module (a small cost-volume
network whose sampling shows lfbench's sign convention in code) and a training config.

:func:`plugin_files` gives the files (relative path -> text); :func:`write_plugin` writes them as one set.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

from lfbench.utils.atomic import fresh_dir
from lfbench.utils.errors import SpecError

#: What a new plugin's network name may be: it becomes a method name, an entry point and (with ``_`` for ``-``)
#: part of a Python package name.
NAME_PATTERN = re.compile(r"[a-z][a-z0-9_-]{0,39}")

PYPROJECT = '''\
# An lfbench plugin made by `lfbench new-plugin __NAME__`. Install it with `pip install .` (or `pip install -e .`).
[build-system]
requires = ["setuptools>=64"]
build-backend = "setuptools.build_meta"

[project]
name = "lfbench-__DIST__"
version = "0.1.0"
description = "The __NAME__ network for lfbench"
requires-python = ">=3.11"
dependencies = ["lfbench"]

# Importing the module registers the network (@register_trainable("__NAME__")): lfbench then trains, evaluates
# (__NAME__:weights=FILE.pt), ablates and times it.
[project.entry-points."lfbench.methods"]
__NAME__ = "__PACKAGE__.plugin"

[tool.setuptools]
packages = ["__PACKAGE__"]
'''

INIT = '''\
"""The __NAME__ network for lfbench (__PACKAGE__.plugin registers it)."""
'''

PLUGIN = '''\
"""The ``__NAME__`` network, registered once with ``@register_trainable``.

Made by ``lfbench new-plugin``: edit it freely and run ``lfbench check-plugin __NAME__`` after each change
(after training, ``lfbench check-plugin __NAME__ --weights RUN/final.pt`` checks the disparity's sign too).
"""

from __future__ import annotations

import math
from typing import Annotated

import torch
from torch import nn
from torch.nn import functional as F

from lfbench import Range, Trainable, register_trainable


class __CLASS__(nn.Module):
    """views (B, N, H, W) float32 gray in [0, 1] -> (disparity (B, H, W) px, probability (B, D, H, W)).

    A matching cost over candidate disparities from the centre row and column of views, refined by 3x3
    convolutions, a softmax over the candidates and its expectation. lfbench's sign (the HCI data's): a point
    of the centre view at (x, y) with disparity d appears in view (u, v) at (x - (u - c) d, y - (v - c) d),
    c = angular // 2; :meth:`cost` samples each view there to compare it with the centre view.
    """

    def __init__(self, channels: Annotated[int, "channels of the 3x3 convolutions over the cost", Range(1, 256)] = 8,
                 layers: Annotated[int, "hidden 3x3 convolutions", Range(1, 16)] = 2,
                 d_min: Annotated[float, "smallest candidate disparity in px", Range(-16, 16)] = -2.0,
                 d_max: Annotated[float, "largest candidate disparity in px", Range(-16, 16)] = 2.0,
                 bins: Annotated[int, "candidate disparities from d_min to d_max", Range(2, 129)] = 9,
                 angular: Annotated[int, "views per angular row (9 for the HCI scenes)", Range(3, 15)] = 9) -> None:
        super().__init__()
        if d_max <= d_min:  # a bad value: ValueError (lfbench makes it one line naming the key)
            raise ValueError(f"d_max must be above d_min, got d_min={d_min}, d_max={d_max}")
        self._config = {"channels": channels, "layers": layers, "d_min": float(d_min), "d_max": float(d_max),
                        "bins": bins, "angular": angular}
        self.angular = angular
        c = angular // 2
        self.register_buffer("disparities", torch.linspace(d_min, d_max, bins), persistent=False)
        # the views of the centre row, then of the centre column (the centre view once): index and (u - c, v - c)
        cross = [(c, u) for u in range(angular)] + [(v, c) for v in range(angular) if v != c]
        self.register_buffer("index", torch.tensor([v * angular + u for v, u in cross]), persistent=False)
        self.register_buffer("offsets", torch.tensor([(u - c, v - c) for v, u in cross], dtype=torch.float32),
                             persistent=False)
        # px of context per output pixel: the farthest sample (c * max |d|, +1 for bilinear) and one px per 3x3
        # convolution; lfbench then runs the network in exact tiles (tile=...)
        self.receptive_radius = math.ceil(c * max(abs(d_min), abs(d_max))) + 1 + layers + 1
        body: list[nn.Module] = []
        cin = bins
        for _ in range(layers):
            body += [nn.Conv2d(cin, channels, 3, padding=1), nn.ReLU()]
            cin = channels
        body.append(nn.Conv2d(cin, bins, 3, padding=1))
        self.refine = nn.Sequential(*body)
        self.sharpness = nn.Parameter(torch.tensor(20.0))  # how strongly a low matching cost wins

    def config(self) -> dict:
        """The constructor's arguments (stored in the weights files lfbench train writes)."""
        return dict(self._config)

    def cost(self, views: torch.Tensor) -> torch.Tensor:
        """(B, N, H, W) -> (B, D, H, W): mean |view - centre view| over the centre row and column, each view
        sampled where a point of disparity d (each of ``disparities``) appears in it."""
        b, _, h, w = views.shape
        cross = views[:, self.index]  # (B, K, H, W)
        k = cross.shape[1]
        centre = cross[:, self.angular // 2: self.angular // 2 + 1]
        xs = torch.arange(w, dtype=views.dtype, device=views.device)  # tensors made from the input's device
        ys = torch.arange(h, dtype=views.dtype, device=views.device)
        su, sv = self.offsets[:, 0, None], self.offsets[:, 1, None]
        costs = []
        for d in self.disparities:
            x = (xs[None] - su * d) * (2 / max(w - 1, 1)) - 1  # (K, W): x - (u - c) d, normalised
            y = (ys[None] - sv * d) * (2 / max(h - 1, 1)) - 1  # (K, H)
            grid = torch.stack(torch.broadcast_tensors(x[:, None, :], y[:, :, None]), dim=-1)  # (K, H, W, 2)
            warped = F.grid_sample(cross.reshape(b * k, 1, h, w), grid.repeat(b, 1, 1, 1), mode="bilinear",
                                   padding_mode="border", align_corners=True).reshape(b, k, h, w)
            costs.append((warped - centre).abs().mean(dim=1))
        return torch.stack(costs, dim=1)

    def forward(self, views: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        cost = self.cost(views)
        prob = torch.softmax((self.refine(cost) - self.sharpness * cost).float(), dim=1)
        return (prob * self.disparities[None, :, None, None]).sum(dim=1), prob


@register_trainable("__NAME__")
class __CLASS__Network(Trainable):
    """A matching cost over candidate disparities refined by a small CNN (made by lfbench new-plugin)."""

    network = __CLASS__
    distribution = True  # forward returns a probability over net.disparities: js, kl, uafl losses apply

    def flops(self, net: __CLASS__, height: int, width: int) -> dict[str, float]:
        """FLOPs of one forward pass on an H x W light field (2 per multiply-add): the convolutions, and about
        10 per sample of the cost (bilinear sampling, difference, mean)."""
        convs = [m for m in net.modules() if isinstance(m, nn.Conv2d)]
        refine = sum(2.0 * m.in_channels * m.out_channels * m.kernel_size[0] * m.kernel_size[1] for m in convs)
        cost = 10.0 * net.disparities.numel() * net.index.numel()
        return {"total": (refine + cost) * height * width, "refine": refine * height * width,
                "cost": cost * height * width}
'''

TRAIN = '''\
# Train __NAME__ on generated scenes (no dataset needed), in seconds on a CPU:
#   lfbench train train___FILE__.toml --out runs/__FILE__
#   lfbench check-plugin __NAME__ --weights runs/__FILE__/final.pt
#   lfbench synth --out runs/__FILE___data --seed 100 --size 64 --scenes 2
#   lfbench evaluate --data runs/__FILE___data --method __NAME__:weights=runs/__FILE__/final.pt --out runs/__FILE__/eval
method = "__NAME__"
seed = 1

[data]
train = ["synthetic"]
patch = 16

[[data.synthetic]]
category = "synthetic"
seed = 3
size = 32
scenes = 4

[model]                     # the network's parameters (lfbench methods lists them)
channels = 8

[training]
batch_size = 4
threads = 1
device = "cpu"

[[stages]]
name = "l1"
loss = "l1"
lr = 1e-3
steps = 40

[[stages]]
name = "js"                 # a distribution loss, from the stage-1 weights
loss = "js"
lr = 1e-4
steps = 10
'''

README = '''\
# __NAME__: an lfbench plugin

```bash
pip install .                               # registers the network __NAME__
lfbench check-plugin __NAME__                # the plugin contract: shapes, tiling, flops, save/load, training
lfbench train train___FILE__.toml --out runs/__FILE__
lfbench check-plugin __NAME__ --weights runs/__FILE__/final.pt   # also the disparity's sign
lfbench info __NAME__                        # parameters, parameter count and FLOPs
```

The network is in `__PACKAGE__/plugin.py`; lfbench's README ("Plugins") gives every hook's contract.
'''


def check_name(name: str) -> None:
    """SpecError unless ``name`` fits :data:`NAME_PATTERN`."""
    if not NAME_PATTERN.fullmatch(name):
        raise SpecError(f"plugin name {name!r}: use 1 to 40 lower-case letters, digits, '_' or '-', starting with a "
                        "letter (it names the network, its entry point and its package)")


def plugin_files(name: str) -> dict[str, str]:
    """The files of a new plugin for network ``name`` (relative path -> text)."""
    check_name(name)
    ident = name.replace("-", "_")
    package = f"lfbench_{ident}"
    words = {"__NAME__": name, "__DIST__": name.replace("_", "-"), "__PACKAGE__": package, "__FILE__": ident,
             "__CLASS__": "".join(part.capitalize() for part in ident.split("_") if part)}

    def fill(text: str) -> str:
        for key, value in words.items():
            text = text.replace(key, value)
        return text

    return {"pyproject.toml": fill(PYPROJECT), f"{package}/__init__.py": fill(INIT),
            f"{package}/plugin.py": fill(PLUGIN), f"train_{ident}.toml": fill(TRAIN), "README.md": fill(README)}


def write_plugin(name: str, out: str | Path) -> list[Path]:
    """Write the plugin of :func:`plugin_files` into the folder ``out`` (created; it must not exist or be
    empty) as one set: written into a fresh folder beside it, then renamed into place. Returns the files."""
    files = plugin_files(name)
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SpecError("exists and is not an empty folder: choose a new --out", out)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = fresh_dir(out.parent, f".{out.name}.", ".new")
    try:
        for rel, text in files.items():
            (staging / rel).parent.mkdir(parents=True, exist_ok=True)
            (staging / rel).write_text(text, encoding="utf-8")
        if out.exists():
            out.rmdir()
        staging.rename(out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return [out / rel for rel in files]


__all__ = ["plugin_files", "write_plugin", "check_name", "NAME_PATTERN"]
