"""The trainable-network seam (lfbench.method.trainable): registration, parameters and axes, config
checks, checkpoints; SubFocal and LFattNet as its users. End to end with a plugin: test_example_plugin."""

from __future__ import annotations

import pytest
import torch
from helpers import isolate_registries
from torch import nn

import lfbench.method.trainable as trainable
from lfbench.method.trainable import Trainable, get_trainable, register_trainable
from lfbench.training import checkpoint as ckpt
from lfbench.training.config import TrainConfig
from lfbench.utils.errors import DataError, SpecError


class Line(nn.Module):
    """disparity = a * centre view + b (no distribution)."""

    def __init__(self, a: float = 1.0, bias: bool = True, angular: int = 3) -> None:
        super().__init__()
        self.angular = angular
        self.a = nn.Parameter(torch.tensor(float(a)))
        self.b = nn.Parameter(torch.zeros(())) if bias else None

    def forward(self, views):
        d = self.a * views[:, views.shape[1] // 2]
        return (d + self.b if self.b is not None else d), None


class LineTrainable(Trainable):
    """A line.

    a: initial slope
    bias: with an offset
    """

    network = Line


@pytest.fixture()
def registry(monkeypatch):
    isolate_registries(monkeypatch)  # the entry points too: subfocal, lfattnet; forgets "line" afterwards
    register_trainable("line")(LineTrainable)
    return trainable.TRAINABLES


def _config(method: str, loss: str = "l1") -> dict:
    return {"method": method, "data": {"synthetic": [{"size": 16, "scenes": 1}]},
            "stages": [{"name": "s", "loss": loss, "lr": 1e-3, "steps": 1}]}


def test_registration_parameters_and_axes(registry):
    t = get_trainable("line")
    assert t.name == "line" and t.method_name == "line" and not t.distribution
    params = t.parameters()
    assert list(params) == ["a", "bias", "angular"] and params["a"].help == "initial slope"
    assert params["a"].default == 1.0 and t.ablation_axes() == ("a", "bias", "angular")
    with pytest.raises(SpecError, match="Unknown trainable network .nope.. Available: .*lfattnet, line, .*subfocal"):
        get_trainable("nope")
    with pytest.raises(TypeError, match="registered as trainable network 'bad' is not a Trainable"):
        register_trainable("bad", registry)(Line)
    with pytest.raises(ValueError, match="\\[model\\] unknown key\\(s\\): slope \\(accepted: a, angular, bias\\)"):
        t.check_params({"slope": 2})


class Counted(Line):
    """Line that records the device of every real build's slope."""

    built: list[str] = []

    def __init__(self, a: float = 1.0, bias: bool = True, angular: int = 3, needs_values: bool = False) -> None:
        if a < 0:
            raise ValueError("a must be >= 0")
        super().__init__(a, bias, angular)
        if needs_values:
            self.a.detach().item()  # reads a value: impossible on the meta device
        Counted.built.append(self.a.device.type)


def test_the_default_check_builds_on_the_meta_device_and_falls_back_to_a_real_build(registry):
    class CountedTrainable(Trainable):
        network = Counted

    t = register_trainable("counted")(CountedTrainable)()
    Counted.built.clear()
    t.check_params({"a": 2.0})
    assert Counted.built == ["meta"]  # shapes only: no memory allocated, no initialisation run
    with pytest.raises(ValueError, match="a must be >= 0"):
        t.check_params({"a": -1.0})
    Counted.built.clear()
    t.check_params({"needs_values": True})
    assert Counted.built == ["cpu"]  # the constructor cannot run on meta: one real build decides
    assert t.build(a=3.0).a.device.type == "cpu"


def test_subfocal_and_lfattnet_are_registered_users_of_the_seam():
    sub, lfa = get_trainable("subfocal"), get_trainable("lfattnet")
    assert sub.distribution and sub.method_name == "subfocal" and lfa.method_name == "lfattnet"
    assert sub.ablation_axes() == ("interval", "interpolation", "width", "attention", "d_min", "d_max")
    assert sub.parameters()["interval"].default == 0.5 and lfa.parameters()["interval"].default == 1.0
    net = lfa.build(width=2)
    assert net.config()["interval"] == 1.0 and net.disparities.numel() == 9
    with pytest.raises(ValueError, match="interpolation must be one of"):
        sub.check_params({"interpolation": "cubic"})


def test_configs_name_the_network_and_its_losses_must_fit(registry, tmp_path):
    cfg = TrainConfig.from_dict(_config("line"))
    assert cfg.method == "line" and cfg.to_dict()["method"] == "line"
    assert "method" not in TrainConfig.from_dict(_config("subfocal")).to_dict()  # the default is left out
    assert TrainConfig.from_dict({k: v for k, v in _config("x").items() if k != "method"}).method == "subfocal"
    with pytest.raises(SpecError, match="method: Unknown trainable network 'nope'"):
        TrainConfig.from_dict(_config("nope"))
    with pytest.raises(SpecError, match="stages\\[0\\].loss: 'uafl' needs a distribution over disparities, which "
                                        "network 'line' does not return"):
        TrainConfig.from_dict(_config("line", "uafl"))


def test_checkpoints_load_back_and_bad_ones_are_refused(registry, tmp_path):
    t = get_trainable("line")
    net = t.build(a=2.0)
    with torch.no_grad():
        net.b.fill_(0.25)
    path = tmp_path / "w.pt"
    ckpt.export_weights(path, net, {}, method="line", config=t.config_of(net, {"a": 2.0}))
    back = t.load(path)
    assert not back.training and back.a.item() == 2.0 and back.b.item() == 0.25
    assert t.load(path, bias=True).b is not None
    with pytest.raises(DataError, match="w.pt: state_dict: weights do not fit the network: 1 unexpected entries"):
        t.load(path, bias=False)
    with pytest.raises(DataError, match="checkpoint config is not valid: .*colour"):
        t.load(path, colour=1)
    (tmp_path / "junk.pt").write_bytes(b"junk")
    with pytest.raises(DataError, match="junk.pt: a text file, not a torch checkpoint"):
        t.load(tmp_path / "junk.pt")


class Oracle(nn.Module):
    """Returns the target when the training loop hands it one (else the centre view), plus a parameter."""

    def __init__(self, angular: int = 9) -> None:
        super().__init__()
        self.angular = angular
        self.w = nn.Parameter(torch.zeros(()))
        self.seen: list[bool] = []

    def forward(self, views, target=None):
        self.seen.append(target is not None)
        base = views[:, views.shape[1] // 2] if target is None else target
        return base + self.w, None


class OracleTrainable(Trainable):
    """An oracle."""

    network = Oracle
    training_target = True


def test_the_training_loop_hands_the_target_to_a_network_that_asks(registry, tmp_path, monkeypatch):
    """training_target: every training forward of lfbench train gets the batch's labels (so an oracle's L1
    loss is 0 exactly), validation none; without the flag, the same network gets none (a loss above 0)."""
    import json

    from lfbench.training.loop import train

    nets: list[Oracle] = []
    monkeypatch.setattr(OracleTrainable, "build", lambda self, **p: nets.append(Oracle(**p)) or nets[-1])
    register_trainable("oracle")(OracleTrainable)
    losses = {}
    for flag in (True, False):
        monkeypatch.setattr(OracleTrainable, "training_target", flag)
        raw = _config("oracle")
        raw["data"]["synthetic"][0]["size"] = 24
        raw["data"].update(train=["synthetic"], validation=["synthetic"], patch=8, texture=0.0)
        raw["training"] = {"batch_size": 2, "device": "cpu"}
        raw["validation"] = {"border": 2}
        raw["stages"][0]["steps"] = 2
        out = tmp_path / str(flag)
        train(TrainConfig.from_dict(raw), out, progress=False, loggers=[])
        entries = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
        losses[flag] = [e["loss"] for e in entries if e.get("event") == "train"]
        assert nets[-1].seen[:2] == [flag, flag] and not nets[-1].seen[-1]  # the last: validation
    assert losses[True] and max(losses[True]) == 0.0 and min(losses[False]) > 0.0
