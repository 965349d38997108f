"""Plugins that misbehave (issue 31, class 5): a network whose forward returns a list, a complex or an
integer tensor, or a map of another size; a constructor or a forward that asks the allocator for 10**12
floats; a constructor that raises RuntimeError; a plain Method whose prediction is not a real map of the
light field's size. Every path that takes a prediction (predict, evaluate, bench, the validation during
training) holds it to the one check (lfbench.data.disparity) and answers with one line, exit 2, nothing
written; never a wrong map with exit 0."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import pytest
import torch
from helpers import assert_one_error_line, isolate_registries, run_cli, write_scene
from torch import nn

from lfbench.data.disparity import check_disparity
from lfbench.data.pfm import read_pfm
from lfbench.data.scene import ArrayLightField
from lfbench.method.base import Method, Prediction
from lfbench.method.registry import register_method
from lfbench.method.trainable import Trainable, register_trainable
from lfbench.training.checkpoint import export_weights
from lfbench.training.data import ValidationScene
from lfbench.training.validate import validate
from lfbench.utils.errors import DataError

SIZE = 32
HUGE = 10**12  # floats: 4 TB, more than any allocator gives


class Hostile(nn.Module):
    """The centre view times a gain, or one of the ways a plugin network misbehaves (``kind``)."""

    def __init__(self, kind: Annotated[str, "how it misbehaves"] = "ok") -> None:
        super().__init__()
        self.angular = 9
        self.kind = kind
        self.gain = nn.Parameter(torch.tensor(1.0))
        if kind == "ctor_raise":
            raise RuntimeError("the plugin's constructor broke")
        if kind == "ctor_alloc":
            self.big = torch.empty(HUGE)  # not a buffer: the meta-device size check cannot see it

    def config(self) -> dict:
        return {"kind": self.kind}

    def forward(self, views):
        d = views[:, views.shape[1] // 2] * self.gain
        out = {"list": lambda: [d], "list3": lambda: [d, None, None], "complex": lambda: (d.to(torch.complex64), None),
               "int": lambda: (d.long(), None), "crop": lambda: (d[..., :-3], None),
               "alloc": lambda: (d + torch.zeros(HUGE).sum(), None),
               "big_only": lambda: (d[..., :-2] if d.shape[-1] > 16 else d, None),
               "nan": lambda: (d * float("nan"), None)}
        return out.get(self.kind, lambda: (d, None))()


class HostileNet(Trainable):
    """A test network that misbehaves as its ``kind`` says."""

    network = Hostile


class Complex(Method):
    """A plain method whose prediction is complex (``kind``) or of another size."""

    def __init__(self, kind: Annotated[str, "what it returns"] = "complex") -> None:
        super().__init__(kind=kind)
        self.kind = kind

    def predict(self, lf):
        h, w = lf.spatial_size
        maps = {"complex": lambda: np.zeros((h, w), np.complex64), "list": lambda: [np.zeros((h, w))],
                "crop": lambda: np.zeros((h, w - 3), np.float32), "ints": lambda: np.zeros((h, w), np.int64),
                "none": lambda: None, "cropped": lambda: np.zeros((h - 4, w - 4), np.float32)}
        return Prediction(disparity=maps[self.kind]())


@pytest.fixture()
def hostile(monkeypatch, tmp_path):
    """'hostile' registered as a network and 'badmap' as a method; the weights of each kind of network."""
    isolate_registries(monkeypatch)
    register_trainable("hostile")(HostileNet)
    register_method("badmap")(Complex)
    scene = write_scene(tmp_path / "data", "tiny", "training", size=SIZE)

    def weights(kind: str) -> Path:
        path = tmp_path / f"{kind}.pt"
        export_weights(path, Hostile(), {}, method="hostile", config={"kind": kind})
        return path

    return {"scene": scene, "root": tmp_path / "data", "weights": weights}


FORWARD = [("list", "forward returned a list of 1, not (disparity, probability or None)"),
           ("list3", "forward returned a list of 3"),
           ("complex", "disparity must be real floating-point values, got torch.complex64"),
           ("int", "disparity must be real floating-point values, got torch.int64"),
           ("crop", f"prediction is {SIZE - 3}x{SIZE}, scene is {SIZE}x{SIZE}"),
           ("alloc", "failed: RuntimeError"),
           ("ctor_raise", "the network's constructor failed: RuntimeError: the plugin's constructor broke"),
           ("ctor_alloc", "the network's constructor failed: RuntimeError")]


@pytest.mark.parametrize(("kind", "problem"), FORWARD, ids=[k for k, _ in FORWARD])
def test_predict_and_evaluate_answer_a_misbehaving_network_in_one_line(hostile, tmp_path, capsys, kind, problem):
    """predict wrote a 61x64 PFM for a 64x64 light field (exit 0), a complex map's real part, an integer map;
    a list, an allocation of 10**12 floats or a RuntimeError in the constructor was a traceback."""
    spec = f"hostile:weights={hostile['weights'](kind)}"
    rc, _, err = run_cli(capsys, "predict", "--method", spec, "--input", hostile["scene"], "--out", tmp_path / "o.pfm")
    line = assert_one_error_line(rc, err, problem)
    assert "tiny" in line or f"{kind}.pt" in line  # names the scene or the weights file
    assert not (tmp_path / "o.pfm").exists()
    rc, _, err = run_cli(capsys, "evaluate", "--data", hostile["root"], "--method", spec, "--out", tmp_path / "ev")
    assert_one_error_line(rc, err, problem)
    assert not (tmp_path / "ev").exists()


def test_a_network_that_keeps_the_contract_writes_its_map_and_counts_non_finite_pixels(hostile, tmp_path, capsys):
    rc, out, err = run_cli(capsys, "predict", "--method", f"hostile:weights={hostile['weights']('ok')}", "--input",
                           hostile["scene"], "--out", tmp_path / "o.pfm")
    assert rc == 0, err
    assert read_pfm(tmp_path / "o.pfm").shape == (SIZE, SIZE)
    rc, out, err = run_cli(capsys, "predict", "--method", f"hostile:weights={hostile['weights']('nan')}", "--input",
                           hostile["scene"], "--out", tmp_path / "n.pfm")
    assert rc == 0, err
    assert f"{SIZE * SIZE} non-finite pixels" in out  # finite or counted
    assert np.isnan(read_pfm(tmp_path / "n.pfm")).all()


METHOD = [("complex", "disparity must be real floating-point values, got complex64"),
          ("ints", "disparity must be real floating-point values, got int64"),
          ("list", f"disparity must be a 2-D map, got shape (1, {SIZE}, {SIZE})"),
          ("none", "disparity must be an array of real floating-point values, got a NoneType"),
          ("crop", f"prediction is {SIZE - 3}x{SIZE}, scene is {SIZE}x{SIZE}")]


@pytest.mark.parametrize(("kind", "problem"), METHOD, ids=[k for k, _ in METHOD])
def test_a_plain_method_is_held_to_the_same_check(hostile, tmp_path, capsys, kind, problem):
    """A Method's complex map was written as its real part (exit 0) and an odd crop as itself."""
    rc, _, err = run_cli(capsys, "predict", "--method", f"badmap:kind={kind}", "--input", hostile["scene"], "--out",
                         tmp_path / "o.pfm")
    assert_one_error_line(rc, err, problem, "on tiny")
    assert not (tmp_path / "o.pfm").exists()
    rc, _, err = run_cli(capsys, "evaluate", "--data", hostile["root"], "--method", f"badmap:kind={kind}", "--out",
                         tmp_path / "ev")
    assert_one_error_line(rc, err, problem)


def test_a_symmetric_crop_within_the_border_is_what_evaluate_aligns(hostile, tmp_path, capsys):
    """predict and evaluate agree: the crop evaluate aligns (2 px a side) is written as it is."""
    rc, _, err = run_cli(capsys, "predict", "--method", "badmap:kind=cropped", "--input", hostile["scene"], "--out",
                         tmp_path / "o.pfm")
    assert rc == 0, err
    assert read_pfm(tmp_path / "o.pfm").shape == (SIZE - 4, SIZE - 4)


def test_check_disparity_by_hand():
    assert check_disparity(np.zeros((4, 6), np.float64), (4, 6), "m").dtype == np.float32
    assert check_disparity(np.zeros((2, 4), np.float16), (4, 6), "m", max_crop=1).shape == (2, 4)
    for bad, expected, max_crop in (((2, 4), (4, 6), 0), ((1, 6), (4, 6), 5), ((0, 2), (4, 6), 1)):
        with pytest.raises(DataError, match=f"prediction is {bad[1]}x{bad[0]}, scene is 6x4"):
            check_disparity(np.zeros(bad, np.float32), expected, "m", max_crop=max_crop)
    with pytest.raises(DataError, match="^m: disparity must be real floating-point values, got bool"):
        check_disparity(np.zeros((4, 6), bool), (4, 6), "m")


@pytest.mark.parametrize(("kind", "problem"), [("complex", "got torch.complex64"), ("list", "a list of 1"),
                                               ("ctor_raise", "RuntimeError: the plugin's constructor broke"),
                                               ("ctor_alloc", "constructor failed: RuntimeError")])
def test_bench_refuses_a_misbehaving_network_before_its_cases(hostile, tmp_path, capsys, kind, problem):
    """bench's forward check let a complex map through; a constructor's RuntimeError was a traceback."""
    monkey_defaults = {"kind": kind}
    HostileNet.defaults = monkey_defaults
    try:
        rc, _, err = run_cli(capsys, "bench", "inference", "--model", "hostile", "--size", "16", "--precision",
                             "fp32", "--json", tmp_path / "b.json")
    finally:
        HostileNet.defaults = {}
    assert_one_error_line(rc, err, "--model hostile", problem)
    assert not (tmp_path / "b.json").exists()


def test_a_bench_case_checks_its_own_output(hostile, one_torch_thread):
    """A network right on the 16 px check but wrong at the case's size: the case is an error, not a time."""
    from lfbench.runs.bench import bench_inference
    from lfbench.utils.errors import SpecError

    with pytest.raises(SpecError, match="prediction is 22x24, scene is 24x24"):
        bench_inference(size=24, model="hostile", device="cpu", max_memory_gb=None, kind="big_only")
    assert bench_inference(size=24, model="hostile", device="cpu", max_memory_gb=None)["seconds"] > 0


@pytest.mark.parametrize(("kind", "problem"), [("list", "a list of 1"), ("complex", "got torch.complex64"),
                                               ("crop", f"prediction is {SIZE - 3}x{SIZE}"),
                                               ("alloc", "the network failed: RuntimeError")])
def test_training_validation_holds_the_network_to_the_same_check(kind, problem, one_torch_thread):
    views = np.random.default_rng(0).uniform(0, 1, (81, SIZE, SIZE)).astype(np.float32)
    scene = ValidationScene("val", views, np.zeros((SIZE, SIZE), np.float32))
    with pytest.raises(DataError, match=f"^validation on val: .*{problem}"):
        validate(Hostile(kind), [scene], torch.device("cpu"), border=2, threshold=0.07)
    assert validate(Hostile(), [scene], torch.device("cpu"), border=2, threshold=0.07)["pixels"] == (SIZE - 4) ** 2


@pytest.mark.parametrize("kind", ["ctor_raise", "ctor_alloc"])
def test_training_with_a_constructor_that_fails_is_one_line(hostile, tmp_path, capsys, kind):
    """A RuntimeError of the constructor (at the check before anything is written, or, for an allocation
    the meta-device check cannot see, at the build) was a traceback."""
    config = tmp_path / "t.toml"
    config.write_text('method = "hostile"\nseed = 1\n[data]\ntrain = ["synthetic"]\npatch = 16\n'
                      '[[data.synthetic]]\ncategory = "synthetic"\nseed = 3\nsize = 32\nscenes = 1\n'
                      f'[model]\nkind = "{kind}"\n[training]\nbatch_size = 1\nthreads = 1\n'
                      '[[stages]]\nname = "l1"\nloss = "l1"\nlr = 1e-3\nsteps = 1\n')
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", tmp_path / "run")
    assert_one_error_line(rc, err, "t.toml", "[model]", "constructor failed: RuntimeError")
    assert not list(tmp_path.glob("run/*.pt"))
    assert kind == "ctor_alloc" or not (tmp_path / "run").exists()


def test_array_light_fields_know_their_size():
    lf = ArrayLightField(np.zeros((9, 9, 5, 7), np.float32))
    assert lf.spatial_size == (5, 7)
