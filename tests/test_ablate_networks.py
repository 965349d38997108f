"""An ablation spec whose cells are different networks (SubFocal's Table III: LFattNet, DistgDisp, OACC-Net and
SubFocal, each with its own disparity range): the ``method`` grid axis, one [[grid]] table per network."""

from __future__ import annotations

from pathlib import Path

import pytest

from lfbench.ablation.spec import load_spec
from lfbench.cli import main

BASE = """
[base]
seed = 3
[base.data]
train = ["synthetic"]
patch = 16
strides = [1]
stride_weights = [1]
[[base.data.synthetic]]
category = "synthetic"
seed = 1
size = 48
scenes = 1
[base.model]
width = 2
interval = 0.1
d_min = -0.5
d_max = 1.6
[base.training]
batch_size = 1
device = "cpu"
[[base.stages]]
name = "l1"
loss = "l1"
lr = 1e-3
steps = 2
[[base.stages]]
name = "uafl"
loss = "uafl"
beta = 0.1
lr = 1e-4
steps = 1
[evaluation]
synthetic = { seed = 5, size = 48, scenes = 1 }
"""

GRIDS = """
[[grid]]
method = ["lfattnet"]
"model.d_min" = [-1]
"model.d_max" = [2]
"model.interval" = [1]
"model.width" = [3]
loss = ["l1"]

[[grid]]
method = ["epinet"]
"model.filters" = [4]
depth = [1]
loss = ["l1"]

[[grid]]
"model.width" = [2]
"""


def _spec(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "t3.toml"
    path.write_text(text + BASE, encoding="utf-8")
    return path


def test_each_grid_table_trains_its_own_network_with_its_own_model(tmp_path):
    spec = load_spec(_spec(tmp_path, GRIDS))
    cells = {c.id: c for c in spec.cells}
    assert list(cells) == ["method=lfattnet_model.d_min=-1_model.d_max=2_model.interval=1_model.width=3_loss=l1",
                           "method=epinet_model.filters=4_depth=1_loss=l1", "model.width=2"]
    att, epi, sub = (c.config for c in spec.cells)
    # The base's [model] is SubFocal's: a cell of another network starts from that network's defaults.
    assert att["method"] == "lfattnet" and att["model"] == {"d_min": -1, "d_max": 2, "interval": 1, "width": 3}
    assert epi["method"] == "epinet" and epi["model"] == {"filters": 4, "depth": 1}
    assert sub.get("method", "subfocal") == "subfocal"
    assert sub["model"] == {"width": 2, "interval": 0.1, "d_min": -0.5, "d_max": 1.6} | {
        k: v for k, v in sub["model"].items() if k not in ("width", "interval", "d_min", "d_max")}
    assert [s["loss"] for s in att["stages"]] == ["l1", "l1"] and sub["stages"][1]["loss"] == "uafl"


@pytest.mark.parametrize("grid, message", [
    ('[[grid]]\nmethod = ["nonet"]\n"model.d_min" = [-1]\n',
     "grid[0].method: 'nonet' is not a registered trainable network (registered: "),
    ('[[grid]]\nmethod = ["epinet"]\n"model.d_min" = [-1]\n', "grid[0] cell method=epinet_model.d_min=-1"),
    ('[[grid]]\nmethod = [3]\n', "grid[0].method: 3 is not a registered trainable network"),
])
def test_an_unknown_network_or_a_parameter_it_lacks_is_one_line(tmp_path, capsys, grid, message):
    path = _spec(tmp_path, grid)
    assert main(["ablate", str(path), "--out", str(tmp_path / "out"), "--list"]) == 2
    err = capsys.readouterr().err
    assert message in err and str(path) in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_each_cell_s_parameters_are_its_own_network_s(tmp_path):
    from lfbench.ablation.report import cell_parameters

    grid = ('[[grid]]\nmethod = ["epinet"]\n"model.depth" = [7]\nloss = ["l1"]\n\n'
            '[[grid]]\nmethod = ["epinet"]\n"model.filters" = [2]\nloss = ["l1"]\n')
    spec = load_spec(_spec(tmp_path, grid))
    got = cell_parameters(spec)
    # The authors' EPINET (9x9 views, 70 filters, 7 blocks) has 5,118,681 trainable parameters.
    assert got["method=epinet_model.depth=7_loss=l1"] == pytest.approx(5.118681, abs=1e-9)
    # Another size: the count of the network built for real.
    import torch

    from lfbench.method.trainable import get_trainable
    net = get_trainable("epinet").build(filters=2)
    assert got["method=epinet_model.filters=2_loss=l1"] * 1e6 == pytest.approx(
        sum(p.numel() for p in net.parameters() if p.requires_grad)) and isinstance(net, torch.nn.Module)
