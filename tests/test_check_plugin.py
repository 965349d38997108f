"""The plugin kit (issue 32.2): ``lfbench check-plugin NAME`` runs a network against every part of the plugin
contract, each failure one line saying what to fix; ``lfbench new-plugin NAME --out DIR`` writes a package
that installs and passes it; ``flops()`` may return a number, and a wrong return is one line naming the hook
and the plugin (it was a bare TypeError in every bench case); ``lfbench info NAME`` shows the parameter
count and FLOPs without weights; the sign convention the README states holds on a generated scene.

The template and examples/tiny_plugin are installed as tests/test_example_plugin.py installs plugins; the
template is checked in a fresh process, the example plugin from the same site in this one; the deliberately
broken networks are registered in this process."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import pytest
import torch
from helpers import assert_one_error_line, install_package, isolate_registries, run_cli
from torch import nn

from lfbench.method.params import Range
from lfbench.method.trainable import Trainable, get_trainable, register_trainable
from lfbench.runs.plugin_check import FAIL, OK, SKIP, check_plugin
from lfbench.training.checkpoint import export_weights
from lfbench.utils.errors import DataError, PluginError, SpecError

ROOT = Path(__file__).resolve().parent.parent
TEMPLATE = "kit-net"


# -- installed plugins, each checked in a fresh process ----------------------------------------------------


@pytest.fixture(scope="module")
def installed(example_plugin, tmp_path_factory):
    """(template source folder, environment whose PYTHONPATH holds the template and examples/tiny_plugin, their
    sites: the template's first)."""
    tmp = tmp_path_factory.mktemp("kit")
    example_site, env = example_plugin
    site = tmp / "site"
    src = tmp / "template"
    proc = subprocess.run([sys.executable, "-m", "lfbench", "new-plugin", TEMPLATE, "--out", str(src)], env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    written = sorted(p.relative_to(src).as_posix() for p in src.rglob("*") if p.is_file())
    assert written == ["README.md", "lfbench_kit_net/__init__.py", "lfbench_kit_net/plugin.py", "pyproject.toml",
                       "train_kit_net.toml"], written
    install_package(src, site)
    return src, {**env, "PYTHONPATH": os.pathsep.join((str(site), env["PYTHONPATH"]))}, (site, example_site)


def _lfbench(env: dict, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lfbench", *map(str, args)], env=env, capture_output=True, text=True,
                          timeout=600)


def _statuses(stdout: str) -> dict[str, str]:
    return {m.group(2): m.group(1) for m in re.finditer(r"^(ok|FAIL|skip)\s+([\w/]+):", stdout, re.M)}


CHECKS = ["build", "forward", "sign", "receptive_radius", "tiling", "flops", "save/load", "training"]


@pytest.mark.slow
def test_the_template_and_the_example_plugin_pass_check_plugin(installed, monkeypatch, capsys, one_torch_thread):
    """The template in a fresh process, as a user runs it (its entry point found in the installed site); the
    example plugin, installed in the same site, in this process (the fresh process would add nothing the
    template's does not show)."""
    src, env, sites = installed
    tiny = _import_tiny()  # before the installed copy is registered below
    assert 'kit-net = "lfbench_kit_net.plugin"' in (src / "pyproject.toml").read_text()
    assert 'method = "kit-net"' in (src / "train_kit_net.toml").read_text()
    proc = _lfbench(env, "check-plugin", TEMPLATE)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    isolate_registries(monkeypatch)
    for site in sites:
        monkeypatch.syspath_prepend(str(site))
    try:
        rc, out, err = run_cli(capsys, "check-plugin", "tinycnn")
        assert rc == 0, out + err
        for stdout in (proc.stdout, out):
            statuses = _statuses(stdout)
            assert list(statuses) == CHECKS, stdout
            # every check runs; the sign needs trained weights (a network with random weights has no sign)
            assert statuses == {c: SKIP if c == "sign" else OK for c in CHECKS}, stdout
            assert "no --weights: a network with random weights has no sign" in stdout
            assert stdout.strip().splitlines()[-1].endswith("passed: 7 ok, 0 failed, 1 skipped")
        # info: parameter count and FLOPs without weights, equal to the network's own
        rc, info, err = run_cli(capsys, "info", "tinycnn:channels=4")
        assert rc == 0, err
    finally:
        for name in [m for m in sys.modules if m.split(".")[0] in ("lfbench_tiny", "lfbench_kit_net")]:
            del sys.modules[name]
    net = tiny.TinyNet(channels=4)
    count = sum(p.numel() for p in net.parameters())
    assert f"parameters: {count:,} ({count:,} trainable)" in info
    convs = [m for m in net.modules() if isinstance(m, nn.Conv2d)]
    gflop = sum(2.0 * m.in_channels * m.out_channels * 9 for m in convs) * 512 * 512 / 1e9
    assert f"FLOPs of one forward pass at 512x512: {gflop:.4g} GFLOP" in info
    assert "network 'tinycnn' (with channels=4, no weights needed)" in info


def _import_tiny():
    sys.path.insert(0, str(ROOT / "examples" / "tiny_plugin"))
    try:
        with pytest.MonkeyPatch.context() as mp:
            isolate_registries(mp)
            import lfbench_tiny.plugin as module
    finally:
        sys.path.pop(0)
        for name in [m for m in sys.modules if m == "lfbench_tiny" or m.startswith("lfbench_tiny.")]:
            del sys.modules[name]
    return module


@pytest.fixture()
def template(installed, monkeypatch):
    """The template's plugin module imported in this process (its network registered as ``kit-net``)."""
    _, _, (site, _) = installed
    isolate_registries(monkeypatch)
    monkeypatch.syspath_prepend(str(site))
    import lfbench_kit_net.plugin as module

    yield module
    for name in [m for m in sys.modules if m.startswith("lfbench_kit_net")]:
        del sys.modules[name]


@pytest.mark.slow
def test_the_sign_check_tells_lfbench_sign_from_the_opposite(template, tmp_path, capsys):
    """With weights, the sign is checked on two generated planes: the template (a matching cost sampled where
    lfbench's convention puts a point) passes with its initial weights; the same network sampling the other way
    fails with the line that says what to flip."""

    class Flipped(template.KitNet):
        """The template sampling each view on the wrong side of the centre."""

        def __init__(self, **kw):
            super().__init__(**kw)
            self.offsets.neg_()

    @register_trainable("kit-flipped")
    class FlippedNetwork(template.KitNetNetwork):
        network = Flipped

    paths = {}
    for name in (TEMPLATE, "kit-flipped"):
        torch.manual_seed(0)
        net = get_trainable(name).build()
        paths[name] = tmp_path / f"{name}.pt"
        export_weights(paths[name], net, {}, method=name, config=net.config())
    good = {f.check: f for f in check_plugin(TEMPLATE, weights=paths[TEMPLATE])}
    assert good["sign"].status == OK, good["sign"]
    plus, minus = map(float, re.findall(r"predicts ([-+][\d.]+) and ([-+][\d.]+)", good["sign"].text)[0])
    assert plus > 0.5 and minus < -0.5  # planes at +1 and -1 px
    rc, out, err = run_cli(capsys, "check-plugin", "kit-flipped", "--weights", paths["kit-flipped"])
    assert rc == 1, out + err
    (line,) = [x for x in out.splitlines() if x.startswith("FAIL")]
    assert line.startswith("FAIL  sign: on planes at +1 and -1 px it predicts -")
    assert "the opposite sign" in line and "appears in view (u, v) at (x - (u - c) d, y - (v - c) d)" in line


# -- deliberately broken networks, one contract broken each --------------------------------------------------


class Base(nn.Module):
    """Two 3x3 convolutions over the views minus the centre view, a softmax over 5 disparities."""

    def __init__(self, hidden: Annotated[int, "hidden channels", Range(1, 64)] = 4) -> None:
        super().__init__()
        self.angular = 9
        self.receptive_radius = 2
        self.register_buffer("disparities", torch.linspace(-2, 2, 5), persistent=False)
        self.a = nn.Conv2d(81, hidden, 3, padding=1)
        self.b = nn.Conv2d(hidden, 5, 3, padding=1)

    def forward(self, views):
        prob = torch.softmax(self.b(torch.relu(self.a(views - views[:, 40:41]))), dim=1)
        return (prob * self.disparities[None, :, None, None]).sum(1), prob


class BaseNet(Trainable):
    """A good network (the reference the broken ones differ from)."""

    network = Base
    distribution = True

    def flops(self, net, height, width):
        return 2 * (81 * net.a.out_channels + net.a.out_channels * 5) * 9 * height * width  # a plain int


class WrongShape(Base):
    def forward(self, views):
        d, p = super().forward(views)
        return d[:, None], p  # (B, 1, H, W)


class Double(Base):
    def forward(self, views):
        d, p = super().forward(views)
        return d.double(), p


class SmallRadius(Base):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.receptive_radius = 1  # two 3x3 convolutions reach 2 px


class FloatRadius(Base):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.receptive_radius = 2.5


class RandomBuffer(Base):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.register_buffer("noise", torch.randn(1, 81, 1, 1), persistent=False)  # not saved: lost on reload

    def forward(self, views):
        return super().forward(views + self.noise)


class Unused(Base):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.spare = nn.Conv2d(4, 4, 1)  # never called


class Broken(Base):
    def __init__(self, **kw):
        super().__init__(**kw)
        raise RuntimeError("forgot to finish __init__")


def _trainable(network: type, **attrs) -> type[Trainable]:
    return type(f"{network.__name__}Net", (BaseNet,), {"network": network, "__module__": __name__, **attrs})


def _list_flops(self, net, height, width):
    return [1.0, 2.0]


def _gflops(self, net, height, width):
    return BaseNet.flops(self, net, height, width) / 1e9  # GFLOPs, not FLOPs


BROKEN = {  # name: (trainable, the failing check, fragments of its line)
    "wrong-shape": (_trainable(WrongShape), "forward",
                    ["disparity is (2, 1, 20, 24)", "return (B, H, W) = (2, 20, 24)"]),
    "double": (_trainable(Double), "forward", ["disparity is torch.float64 in fp32: return float32"]),
    "small-radius": (_trainable(SmallRadius), "receptive_radius",
                     ["declared 1 px, but a change of one pixel moved outputs 2 px away",
                      "declare receptive_radius >= 2"]),
    "float-radius": (_trainable(FloatRadius), "receptive_radius", ["receptive_radius is 2.5 (float): declare an int"]),
    "list-flops": (_trainable(Base, flops=_list_flops), "flops",
                   ["network 'list-flops' (test_check_plugin.BaseNet", "flops() returned a list: return the FLOPs of "
                    "one forward pass on an H x W light field: a number, or {'total': n, ...}"]),
    "giga-flops": (_trainable(Base, flops=_gflops), "flops",
                   ["torch's FLOP counter measures", "count FLOPs (2 per multiply-add, not GFLOPs or MACs)"]),
    "random-buffer": (_trainable(RandomBuffer), "save/load", ["the reloaded network's output differs by",
                                                               "persistent buffer"]),
    "unused": (_trainable(Unused), "training",
               ["2 parameter(s) get no gradient from the l1+js loss (spare.weight, spare.bias)", "never trained"]),
    "broken": (_trainable(Broken), "build", ["broken() raised RuntimeError: forgot to finish __init__"]),
}


@pytest.fixture()
def broken(monkeypatch):
    isolate_registries(monkeypatch)
    register_trainable("base")(BaseNet)
    for name, (cls, _, _) in BROKEN.items():
        register_trainable(name)(cls)


def test_a_good_network_passes_and_each_broken_one_fails_its_check_with_its_line(broken, capsys):
    rc, out, err = run_cli(capsys, "check-plugin", "base")
    assert rc == 0, out + err
    assert _statuses(out) == {c: SKIP if c == "sign" else OK for c in CHECKS}
    assert f"flops: {BaseNet.flops(None, Base(), 20, 24):.4g} FLOPs at 20x24;" in out  # the int flops() returns
    for name, (_, check, fragments) in BROKEN.items():
        rc, out, err = run_cli(capsys, "check-plugin", name)
        assert rc == 1 and "Traceback" not in err, (name, out, err)
        failures = [line for line in out.splitlines() if line.startswith("FAIL")]
        mine = [line for line in failures if line.startswith(f"FAIL  {check}: ")]
        assert len(mine) == 1, (name, out)
        for fragment in fragments:
            assert fragment in mine[0], (name, fragment, mine[0])
        if name == "small-radius":  # too small a radius also breaks tiling, which says so
            assert [line.split(":")[0] for line in failures] == ["FAIL  receptive_radius", "FAIL  tiling"]
            assert "tiles of 8 px differ from the whole image" in failures[1]
        elif name == "broken":  # nothing else can run
            assert _statuses(out) == {"build": FAIL, **{c: SKIP for c in CHECKS[1:]}}
        else:
            assert len(failures) == 1, (name, out)
        assert out.strip().splitlines()[-1].endswith(f"FAILED: {sum(s == OK for s in _statuses(out).values())} ok, "
                                                     f"{len(failures)} failed, "
                                                     f"{sum(s == SKIP for s in _statuses(out).values())} skipped")


def test_bad_input_is_one_line_exit_2(broken, capsys, tmp_path):
    assert_one_error_line(*run_cli(capsys, "check-plugin", "nosuchnet")[::2], "nosuchnet")
    assert_one_error_line(*run_cli(capsys, "check-plugin", "base:hidden=0")[::2], "hidden: must be in [1, 64], got 0")
    assert_one_error_line(*run_cli(capsys, "check-plugin", "base", "--weights", tmp_path / "no.pt")[::2],
                          "no.pt: weights file not found")
    (tmp_path / "w.json").write_text("{}")
    assert_one_error_line(*run_cli(capsys, "check-plugin", "base", "--weights", tmp_path / "w.json")[::2],
                          "w.json: a JSON file, not a torch checkpoint")
    rc, _, err = run_cli(capsys, "new-plugin", "Bad Name", "--out", tmp_path / "p")
    assert_one_error_line(rc, err, "plugin name 'Bad Name'")
    rc, _, err = run_cli(capsys, "new-plugin", "base", "--out", tmp_path / "p")
    assert_one_error_line(rc, err, "a method or network named 'base' is registered already")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    rc, _, err = run_cli(capsys, "new-plugin", "fresh", "--out", tmp_path / "full")
    assert_one_error_line(rc, err, "full: exists and is not an empty folder")
    assert not (tmp_path / "p").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["full", "w.json"]


def test_flops_may_be_a_number_and_a_wrong_return_names_the_hook_and_the_plugin(broken):
    """A number was a bare ``TypeError: 'int' object is not subscriptable`` in every bench case."""
    from lfbench.runs.bench import bench_inference

    threads = torch.get_num_threads()
    try:
        record = bench_inference(16, model="base", threads=1)
        with pytest.raises(PluginError) as info:
            bench_inference(16, model="list-flops", threads=1)
    finally:
        torch.set_num_threads(threads)
    expected = BaseNet.flops(None, Base(), 16, 16)
    assert record["tflop"] == pytest.approx(expected / 1e12) and record["gflops_per_s"] > 0
    # what users naturally return is read as the total: a number, a one-element tensor, a dict with a total
    trainable = get_trainable("base")
    for value in (expected, float(expected), torch.tensor(float(expected)), np.float64(expected),
                  {"total": expected, "convs": torch.tensor(expected)}):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(BaseNet, "flops", lambda self, net, h, w, v=value: v)
            assert trainable.flop_count(Base(), 16, 16)["total"] == expected, value
    assert str(info.value) == ("network 'list-flops' (test_check_plugin.BaseNet): flops() returned a list: return the "
                               "FLOPs of one forward pass on an H x W light field: a number, or {'total': n, ...}")
    assert info.value.exit_code == 1


def test_info_shows_parameters_and_flops_without_weights(broken, capsys):
    rc, out, err = run_cli(capsys, "info", "base:hidden=6")
    assert rc == 0, err
    net = Base(hidden=6)
    count = sum(p.numel() for p in net.parameters())
    assert f"network 'base' (with hidden=6, no weights needed):\n  parameters: {count:,} ({count:,} trainable)" in out
    assert f"FLOPs of one forward pass at 512x512: {BaseNet.flops(None, net, 512, 512) / 1e9:.4g} GFLOP" in out
    rc, out, _ = run_cli(capsys, "info", "unused")  # no flops of its own: BaseNet's int
    assert "parameters:" in out


def test_the_readme_sign_convention_holds_on_a_generated_scene():
    """README: a point of the centre view at (x, y) with disparity d appears in view (u, v) at (x - (u - c) d,
    y - (v - c) d): on a generated plane at d = +1 px, the view right of the centre is the centre view moved one
    px left, and the view below it one px up (the opposite shifts do not match)."""
    from lfbench.data.synth import plane_views

    readme = " ".join((ROOT / "README.md").read_text().split())
    assert "appears in view (u, v) at (x - (u - c) d, y - (v - c) d)" in readme
    views = plane_views(1.0, 40, 9)
    c = 4
    centre, right, below = views[c, c], views[c, c + 1], views[c + 1, c]

    def err(a, b):
        return float(np.abs(a - b)[4:-4, 4:-4].mean())

    assert err(right[:, :-1], centre[:, 1:]) < 0.2 * err(right[:, 1:], centre[:, :-1])  # right(x) = centre(x + d)
    assert err(below[:-1], centre[1:]) < 0.2 * err(below[1:], centre[:-1])
    assert err(right[:, :-1], centre[:, 1:]) < 0.01


def test_a_missing_weights_file_for_the_sign_check_is_bad_input(broken, tmp_path):
    with pytest.raises(DataError):
        check_plugin("base", weights=tmp_path / "none.pt")
    with pytest.raises(SpecError, match="hidden"):
        check_plugin("base", {"hidden": 0})


LIST_FLOPS_PLUGIN = '''\
from torch import nn

from lfbench import Trainable, register_trainable


class Net(nn.Module):
    def __init__(self):
        super().__init__()
        self.angular = 9
        self.conv = nn.Conv2d(81, 1, 3, padding=1)

    def forward(self, views):
        return self.conv(views)[:, 0], None


@register_trainable("listflops")
class ListFlops(Trainable):
    network = Net

    def flops(self, net, height, width):
        return [1.0]
'''


def test_a_bench_case_of_a_wrong_flops_is_one_line_naming_the_hook_and_the_plugin(tmp_path, monkeypatch):
    """As a user meets it: ``lfbench bench`` runs each case in a fresh process, where the plugin is installed."""
    from lfbench.runs.bench import run_isolated

    site = tmp_path / "site"
    dist = site / "listflops_plugin-1.0.dist-info"
    dist.mkdir(parents=True)
    (site / "listflops_plugin.py").write_text(LIST_FLOPS_PLUGIN)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: listflops-plugin\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[lfbench.methods]\nlistflops = listflops_plugin\n")
    monkeypatch.setenv("PYTHONPATH", str(site))
    record = run_isolated("inference", {"size": 16, "model": "listflops", "threads": 1}, timeout_s=300)
    assert record["error"] == ("exit 1: error: network 'listflops' (listflops_plugin.ListFlops): flops() returned a "
                               "list: return the FLOPs of one forward pass on an H x W light field: a number, or "
                               "{'total': n, ...}")
