"""The training config, declared once (issue 21.4) and checked whole before anything is generated or written
(issue 22.3): one-line errors naming the file and the key for wrong types, bounds and keys, the network's
[model] parameters against its annotations, data names against the data; only the synthetic sets a run
reads are generated; the optimizer comes from the trainable network (Trainable.configure_optimizers)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any, Literal

import pytest
import torch
from helpers import assert_one_error_line, run_cli

from lfbench.training.config import RESUME_FREE_KEYS, STAGE_KEYS, DataConfig, TrainConfig
from lfbench.utils.errors import SpecError
from lfbench.utils.options import TypeMismatch, coerce
from lfbench.utils.tomlfile import toml_text


def config(**changes: dict) -> dict:
    """A tiny config on one synthetic set (generated into OUT/data when the run starts), with ``changes``
    written over its tables (table name -> {key: value}; "" for the top level)."""
    cfg = {"seed": 1,
           "data": {"train": ["synthetic"], "patch": 16, "strides": [1], "stride_weights": [1],
                    "synthetic": [{"category": "synthetic", "seed": 1, "size": 24, "scenes": 1}]},
           "model": {"width": 2, "interval": 1.0},
           "training": {"batch_size": 1, "threads": 1, "checkpoint_every": 1, "log_every": 1, "prefetch": 0},
           "validation": {"every": 0},
           "stages": [{"name": "l1", "loss": "l1", "lr": 1e-3, "steps": 2}]}
    for table, values in changes.items():
        (cfg.setdefault(table, {}) if table else cfg).update(values)
    return cfg


def write_config(path: Path, cfg: dict) -> Path:
    path.write_text(toml_text(cfg))
    return path


@pytest.mark.parametrize(("change", "problem"), [
    ({"training": {"batch_size": "3"}}, "training.batch_size: expected int, got str"),
    ({"training": {"batch_size": 3.5}}, "training.batch_size: expected int, got float"),
    ({"training": {"batch_size": True}}, "training.batch_size: expected int, got bool"),
    ({"training": {"precision": "fp16"}}, "training.precision: expected one of 'fp32', 'bf16', got 'fp16'"),
    ({"training": {"batch": 3}}, "[training] unknown key(s): batch (accepted: accumulate, batch_size, channels_last"),
    ({"": {"sed": 3}}, "unknown key(s): sed (accepted: augment, data, init, method, model, out, seed, stages"),
    ({"data": {"patch": 4}}, "data.patch: must be in [8, 1024], got 4"),
    ({"data": {"roots": ["a", 1]}}, "data.roots: expected list of str, got list of int and str"),
    ({"data": {"stride_weights": [1, -1], "strides": [1, 2]}},
     "data.stride_weights: expected numbers >= 0, got [1.0, -1.0]"),
    ({"augment": {"gamma": [1.2]}}, "augment.gamma: expected list of 2 float, got list of 1"),
    ({"augment": {"gamma": [1.2, 0.8]}}, "augment.gamma: expected [low, high] with 0 < low <= high"),
    ({"augment": {"flip": float("nan")}}, "augment.flip: must be a finite number, got nan"),
    ({"model": {"width": "16"}}, "model.width: expected int, got str"),
    ({"model": {"width": 16.5}}, "model.width: expected int, got float"),
    ({"model": {"interval": True}}, "model.interval: expected float, got bool"),
    ({"model": {"widht": 16}}, "[model] unknown key(s): widht (accepted: angular, attention, d_max, d_min, "
                               "interpolation, interval, width)"),
    # the network's own check of a value, before the data is generated or anything is written
    ({"model": {"width": 0}}, "model.width: must be in [1, 1024], got 0"),
    ({"model": {"interpolation": "bicubic"}}, "[model]: interpolation must be one of"),
    # data names: checked against the data roots and the synthetic sets the run would generate
    ({"data": {"validation": ["nosuch"]}}, "[data] no scene 'nosuch'; available: synth_1_0"),
    ({"data": {"validation": ["synthetic"]}, "validation": {"border": 12}},
     "validation.border = 12 leaves no pixel of validation scene 'synth_1_0'"),
], ids=lambda v: str(v)[:40] if isinstance(v, str) else None)
def test_a_bad_config_is_one_line_and_nothing_is_generated_or_written(tmp_path, capsys, change, problem):
    path = write_config(tmp_path / "c.toml", config(**change))
    rc, _, err = run_cli(capsys, "-q", "train", path, "--out", tmp_path / "run", "--no-progress")
    assert_one_error_line(rc, err, "c.toml", problem)
    assert not (tmp_path / "run").exists()  # no folder, no synthetic data, no log


def test_the_config_without_errors_trains(tmp_path, capsys, one_torch_thread):
    """The base of the cases above is a valid config (so each case fails for its own change only)."""
    path = write_config(tmp_path / "c.toml", config())
    rc, _, err = run_cli(capsys, "-q", "train", path, "--out", tmp_path / "run", "--no-progress")
    assert rc == 0, err
    assert [p.name for p in (tmp_path / "run" / "data").iterdir()] == ["synthetic"]


def test_only_the_synthetic_sets_a_run_reads_are_generated(tmp_path):
    """data.validation = [] leaves the validation set of the base config ungenerated (it used to be written)."""
    from lfbench.training.scenes import prepare_synthetic

    def sets(train: list[str], validation: list[str]) -> TrainConfig:
        sets = [{"category": "synthetic", "seed": 1, "size": 16, "scenes": 1},
                {"category": "synthetic_val", "seed": 2, "size": 16, "scenes": 2}]
        return TrainConfig.from_dict({"data": {"train": train, "validation": validation, "synthetic": sets},
                                      "model": {"width": 2}, "stages": [{"loss": "l1", "steps": 1}]})

    def in_use(cfg: TrainConfig) -> list[str]:
        return [s.category for s in cfg.data.synthetic_in_use()]

    assert in_use(sets(["synthetic"], [])) == ["synthetic"]
    assert in_use(sets(["synthetic"], ["synthetic_val"])) == ["synthetic", "synthetic_val"]
    assert in_use(sets(["synthetic"], ["synth_2_1"])) == ["synthetic", "synthetic_val"]  # by scene name
    assert in_use(sets([], [])) == ["synthetic", "synthetic_val"]  # every scene with gt trains
    assert in_use(sets(["antinous"], [])) == []
    prepare_synthetic(sets(["synthetic"], []), tmp_path, log=lambda _: None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["synthetic"]
    assert sorted(p.name for p in (tmp_path / "synthetic").iterdir()) == ["synth_1_0"]


def test_resume_free_keys_and_stage_keys_come_from_the_declarations():
    """The sets the loop and the ablation spec hard-coded before the options were declared once."""
    assert set(RESUME_FREE_KEYS) == {
        ("out",), ("training", "threads"), ("training", "prefetch"), ("training", "log_every"),
        ("training", "device"), ("training", "checkpoint_every"), ("training", "channels_last"),
        ("training", "workers"), ("training", "pin_memory"), ("training", "cudnn_benchmark")}
    assert STAGE_KEYS == {"name", "loss", "lr", "steps", "eps", "betas"}


def test_to_dict_leaves_out_the_keys_added_later_at_their_defaults():
    """Configs and cell fingerprints written before method, init and the throughput keys existed stay the same."""
    cfg = TrainConfig.from_dict({"data": {"roots": ["r"]}, "stages": [{"loss": "l1", "steps": 1}]})
    d = cfg.to_dict()
    assert "method" not in d and "init" not in d
    assert set(d["training"]) == {"batch_size", "accumulate", "threads", "device", "checkpoint_every", "log_every",
                                  "prefetch", "channels_last"}
    assert d["out"] is None and d["data"]["invalid_area"] is None  # kept: they were there from the start
    assert d["stages"] == [{"name": "stage1", "loss": "l1", "lr": 1e-3, "steps": 1, "eps": 1e-7,
                            "betas": [0.9, 0.999]}]
    changed = TrainConfig.from_dict({**d, "training": {**d["training"], "workers": 2, "tf32": True}})
    assert changed.to_dict()["training"]["workers"] == 2 and changed.to_dict()["training"]["tf32"] is True
    assert TrainConfig.from_dict(changed.to_dict()) == changed


def test_a_stage_takes_its_loss_parameters_beside_its_keys():
    cfg = TrainConfig.from_dict({"data": {"roots": ["r"]}, "stages": [
        {"loss": " UAFL ", "beta": 0.5, "steps": 1}, {"name": "x", "loss": "l1", "steps": 2}]})
    assert [(s.name, s.loss, s.loss_params) for s in cfg.stages] == [("stage1", "uafl", {"beta": 0.5}),
                                                                     ("x", "l1", {})]
    assert cfg.to_dict()["stages"][0]["beta"] == 0.5
    with pytest.raises(SpecError, match=r"stages\[1\]: loss 'l1' has no parameter gamma"):
        TrainConfig.from_dict({"data": {"roots": ["r"]}, "stages": [
            {"loss": "l1", "steps": 1}, {"loss": "l1", "gamma": 1, "steps": 1}]})
    with pytest.raises(SpecError, match=r"stages\[0\].steps: is required"):
        TrainConfig.from_dict({"data": {"roots": ["r"]}, "stages": [{"loss": "l1"}]})
    with pytest.raises(SpecError, match="stages: needs at least 1 entry"):
        TrainConfig.from_dict({"data": {"roots": ["r"]}, "stages": []})


def test_a_table_given_where_an_array_of_tables_is_declared_is_one_entry():
    one = TrainConfig.from_dict({"data": {"train": "synthetic", "synthetic": {"scenes": 2}},
                                 "stages": [{"loss": "l1", "steps": 1}]})
    assert one.data.train == ("synthetic",) and [s.scenes for s in one.data.synthetic] == [2]
    assert DataConfig().stride_weights == (8.0, 6.0, 3.0)
    two = TrainConfig.from_dict({"data": {"roots": ["r"], "strides": [1, 2]}, "stages": [{"loss": "l1", "steps": 1}]})
    assert two.data.stride_weights == (1.0, 1.0)  # one each when not three strides


@pytest.mark.parametrize(("value", "kind", "expected"), [
    (3, float, 3.0), (3, int, 3), ("a", Literal["a", "b"], "a"), (None, int | None, None), (2, int | None, 2),
    ([1, 2.5], tuple[float, ...], (1.0, 2.5)), ([1, 2], tuple[int, int], (1, 2)), ({"a": 1}, dict[str, float],
                                                                                  {"a": 1.0}),
    (7, Annotated[int, "help text"], 7), ({"x": [1]}, dict[str, Any], {"x": [1]}), ("x", Any, "x"),
    (5, "int", 5),  # an annotation that is not a type (unresolved): not checked here
    ("a/b", Path | None, Path("a/b")),
])
def test_coerce_accepts_values_of_the_declared_type(value, kind, expected):
    got = coerce(value, kind)
    assert got == expected and type(got) is type(expected)


@pytest.mark.parametrize(("value", "kind", "message"), [
    ("3", int, "expected int, got str"), (3.0, int, "expected int, got float"), (True, int, "expected int, got bool"),
    (True, float, "expected float, got bool"), (1, str, "expected str, got int"), ("c", Literal["a", "b"],
                                                                                  "expected one of 'a', 'b', got 'c'"),
    ([1, "x"], tuple[int, ...], "expected list of int, got list of int and str"),
    ([1], tuple[float, float], "expected list of 2 float, got list of 1"),
    (1, tuple[str, ...], "expected list of str, got int"),
    ({"a": "x"}, dict[str, float], "expected table of float, got a table with list of str"),
    ("16", Annotated[int, "channels"], "expected int, got str"),
    (5, str | None, "expected str, got int"), (5, Path | None, "expected path, got int"),
])
def test_coerce_names_both_types_and_never_the_value(value, kind, message):
    with pytest.raises(TypeMismatch) as info:
        coerce(value, kind)
    assert str(info.value) == message


# --------------------------------------------------------------------------- the optimizer from the trainable

@pytest.fixture()
def sgd_network(monkeypatch):
    """'subfocal_sgd': SubFocal optimised with SGD and a learning rate halved after every step (a schedule
    with a state), registered for this test only."""
    from helpers import isolate_registries
    from lfbench_methods.subfocal.trainable import SubFocalTrainable

    from lfbench.method.trainable import register_trainable

    class SGDSubFocal(SubFocalTrainable):
        def configure_optimizers(self, net, stage):
            optimizer = torch.optim.SGD(net.parameters(), lr=stage.lr, momentum=0.9)
            return optimizer, torch.optim.lr_scheduler.StepLR(optimizer, step_size=1, gamma=0.5)

    isolate_registries(monkeypatch)
    register_trainable("subfocal_sgd")(SGDSubFocal)
    return "subfocal_sgd"


class _StopAt:
    """A run logger that stops the run (as a kill would) once the training log reaches global step ``at``."""

    def __init__(self, at: int) -> None:
        self.at = at

    def record(self, entry: dict) -> None:
        if entry.get("event") == "train" and entry["global_step"] == self.at:
            raise KeyboardInterrupt

    def close(self) -> None:
        pass


def test_the_optimizer_and_its_schedule_come_from_the_trainable_and_resume_exactly(tmp_path, sgd_network,
                                                                                     one_torch_thread):
    from lfbench.training.loop import train

    cfg = config(**{"": {"method": sgd_network}, "training": {"checkpoint_every": 2}})
    cfg["stages"][0]["steps"] = 4
    cfg = TrainConfig.from_toml(write_config(tmp_path / "c.toml", cfg))
    train(cfg, tmp_path / "whole", progress=False, loggers=[])
    log = [json.loads(line) for line in (tmp_path / "whole" / "metrics.jsonl").read_text().splitlines()]
    assert [e["lr"] for e in log if e["event"] == "train"] == [1e-3, 5e-4, 2.5e-4, 1.25e-4]  # the schedule's
    state = torch.load(tmp_path / "whole" / "checkpoint.pt", weights_only=True)
    assert state["optimizer"] is None and "schedule" not in state  # a stage boundary: a fresh optimizer next

    with pytest.raises(KeyboardInterrupt):  # killed after step 3, after the checkpoint of step 2
        train(cfg, tmp_path / "cut", progress=False, loggers=[_StopAt(3)])
    state = torch.load(tmp_path / "cut" / "checkpoint.pt", weights_only=True)
    assert (state["step"], state["schedule"]["last_epoch"]) == (2, 2)
    assert state["optimizer"]["state"]  # SGD's momentum buffers
    train(cfg, tmp_path / "cut", progress=False, loggers=[])
    whole = torch.load(tmp_path / "whole" / "final.pt", weights_only=True)["state_dict"]
    resumed = torch.load(tmp_path / "cut" / "final.pt", weights_only=True)["state_dict"]
    assert all(torch.equal(whole[k], resumed[k]) for k in whole)


def test_the_default_optimizer_is_adam_with_the_stage_settings():
    from lfbench.method.trainable import get_trainable

    cfg = TrainConfig.from_dict({"data": {"roots": ["r"]}, "stages": [
        {"loss": "l1", "steps": 1, "lr": 2e-3, "eps": 1e-6, "betas": [0.8, 0.9]}]})
    net = torch.nn.Linear(2, 1)
    optimizer = get_trainable(cfg.method).configure_optimizers(net, cfg.stages[0])
    assert type(optimizer) is torch.optim.Adam
    group = optimizer.param_groups[0]
    assert (group["lr"], group["eps"], group["betas"]) == (2e-3, 1e-6, (0.8, 0.9))
