"""The generic network method (lfbench.method.network_method): a network registered once
(@register_trainable) runs as NAME:weights=PATH; the two-class style (a Trainable and a Method of its own)
still works; weights are named by content in results (a move does not change a record's key); foreign
files and conflicting parameters are one line; tiles are exact. End to end through the CLI with an
installed plugin: test_example_plugin and test_plugin_from_readme."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import pytest
import torch
from helpers import isolate_registries, write_scene
from torch import nn

from lfbench.data.hci import HCIScene
from lfbench.data.scene import ArrayLightField
from lfbench.method.base import Method, Prediction
from lfbench.method.network_method import NetworkMethod
from lfbench.method.params import Range
from lfbench.method.registry import REGISTRY, create, create_from_spec, register_method
from lfbench.method.trainable import Trainable, get_trainable, register_trainable
from lfbench.results import Results
from lfbench.runs.folder import evaluate_to_folder
from lfbench.runs.regress import check, read_golden
from lfbench.training.checkpoint import export_weights
from lfbench.utils.errors import DataError, SpecError


class Stack(nn.Module):
    """Two 3x3 convolutions over the views minus the centre view, a softmax over 5 disparities."""

    def __init__(self, hidden: Annotated[int, "hidden channels", Range(1, 64)] = 4,
                 scale: Annotated[float, "scale of the candidate disparities in px"] = 1.0,
                 angular: Annotated[int, "views per angular row"] = 9) -> None:
        super().__init__()
        self.angular = angular
        self.receptive_radius = 2  # two 3x3 convolutions
        self.register_buffer("disparities", torch.linspace(-2, 2, 5) * scale, persistent=False)
        self.a = nn.Conv2d(angular * angular, hidden, 3, padding=1)
        self.b = nn.Conv2d(hidden, 5, 3, padding=1)

    def forward(self, views):
        centre = views.shape[1] // 2
        prob = torch.softmax(self.b(torch.relu(self.a(views - views[:, centre:centre + 1]))), dim=1)
        return (prob * self.disparities[None, :, None, None]).sum(1), prob


class StackNet(Trainable):
    """A two-layer stack (a test network)."""

    network = Stack
    distribution = True


class Whole(nn.Module):
    """The centre view times ``gain``: no receptive radius declared (whole images only)."""

    def __init__(self, gain: Annotated[float, "factor on the centre view"] = 1.0) -> None:
        super().__init__()
        self.angular = 9
        self.gain = nn.Parameter(torch.tensor(float(gain)))

    def forward(self, views):
        return views[:, views.shape[1] // 2] * self.gain, None


class WholeNet(Trainable):
    """The centre view (a test network without a distribution)."""

    network = Whole


class StackMethod(Method):
    """The two-class style: a method of its own running the weights of the trainable 'stack2'."""

    def __init__(self, weights: Annotated[Path, "weights file"]) -> None:
        super().__init__(weights=weights)
        self.weights = Path(weights)

    def predict(self, lf):
        net = get_trainable("stack2").load(self.weights)
        views = torch.from_numpy(np.ascontiguousarray(lf.gray_views().reshape(1, 81, *lf.gray_views().shape[2:])))
        with torch.inference_mode():
            disparity, _ = net(views)
        return Prediction(disparity=disparity[0].numpy())


@pytest.fixture()
def nets(monkeypatch, tmp_path):
    """Registered: 'stack' (one class), 'stack2' (two classes), 'whole'; weights of each written."""
    isolate_registries(monkeypatch)
    register_trainable("stack")(StackNet)
    register_trainable("stack2")(StackNet)
    register_method("stack2")(StackMethod)
    register_trainable("whole")(WholeNet)
    torch.manual_seed(0)
    paths = {}
    for name, trainable in (("stack", StackNet), ("stack2", StackNet), ("whole", WholeNet)):
        net = trainable().build()
        with torch.no_grad():
            for p in net.parameters():
                p.add_(torch.randn_like(p) * 0.3)
        paths[name] = tmp_path / f"{name}.pt"
        export_weights(paths[name], net, {}, method=name, config=get_trainable(name).config_of(net, {}))
    return paths


def _lf(size: int = 20, seed: int = 1) -> ArrayLightField:
    views = np.random.default_rng(seed).uniform(0, 1, (9, 9, size, size)).astype(np.float32)
    return ArrayLightField(views, name="toy")


def _reference(path: Path, lf: ArrayLightField) -> tuple[np.ndarray, np.ndarray]:
    """The network rebuilt by hand from the weights file and run on the whole light field, on one thread (as
    the method runs with threads=1: the same kernels, so the same float rounding)."""
    from lfbench.utils.threads import torch_threads

    payload = torch.load(path, map_location="cpu", weights_only=True)
    net = Stack(**payload["config"])
    net.load_state_dict(payload["state_dict"])
    views = torch.from_numpy(lf.gray_views().reshape(1, 81, *lf.gray_views().shape[2:]))
    with torch.inference_mode(), torch_threads(1):
        d, p = net.eval()(views)
    return d[0].numpy(), p[0].numpy()


def test_a_network_registered_once_runs_as_a_method(nets):
    info = REGISTRY.info("stack")
    assert info.method_class is NetworkMethod and info.network == "stack"
    assert {"weights", "device", "precision", "threads", "tile", "hidden", "scale", "angular"} == set(info.params)
    text = info.describe()
    assert "network parameters (with weights=..., the weights' own" in text
    assert "hidden (int [1, 64], default 4): hidden channels" in text
    lf = _lf()
    method = create_from_spec(f"stack:weights={nets['stack']},device=cpu,threads=1")
    assert isinstance(method, NetworkMethod) and method.available_for(lf) is None
    pred = method.run(lf)
    disparity, probability = _reference(nets["stack"], lf)
    np.testing.assert_array_equal(pred.disparity, disparity)
    np.testing.assert_array_equal(pred.distribution, probability)
    np.testing.assert_array_equal(pred.disparity_values, np.linspace(-2, 2, 5, dtype=np.float32))
    d = np.linspace(-2, 2, 5)[:, None, None]  # the uncertainty: the distribution's standard deviation, px
    std = np.sqrt((probability * (d - disparity[None]) ** 2).sum(0))
    np.testing.assert_allclose(pred.uncertainty, std, rtol=1e-5, atol=1e-6)
    # without weights it does not run (never random weights), and says why
    reason = create("stack").available_for(lf)
    assert reason.startswith("no weights: give stack:weights=FILE.pt")


def test_tiles_are_exact_and_a_network_without_a_receptive_radius_runs_whole(nets):
    lf = _lf(23)
    whole = create("stack", weights=nets["stack"], device="cpu").run(lf)
    for tile in (5, 8, 16):  # equal up to float rounding (a halo too small is off by 0.1 px and more)
        tiled = create("stack", weights=nets["stack"], device="cpu", tile=tile).run(lf)
        np.testing.assert_allclose(tiled.disparity, whole.disparity, atol=1e-5, rtol=0)
        np.testing.assert_allclose(tiled.distribution, whole.distribution, atol=1e-5, rtol=0)
    gain = float(torch.load(nets["whole"], weights_only=True)["state_dict"]["gain"])
    pred = create("whole", weights=nets["whole"]).run(lf)
    np.testing.assert_allclose(pred.disparity, lf.gray_views()[4, 4] * gain, rtol=1e-6)
    assert pred.distribution is None and pred.uncertainty is None
    with pytest.raises(SpecError, match="tile=8, but network 'whole' runs on whole images only"):
        create("whole", weights=nets["whole"], tile=8).run(lf)


def test_the_two_class_style_still_works(nets):
    info = REGISTRY.info("stack2")
    assert info.method_class is StackMethod and list(info.params) == ["weights"]
    text = info.describe()  # the network's parameters are listed beside the method's own
    assert "weights (path, required): weights file" in text
    assert "network parameters (the [model] keys of lfbench train and the ablation axes of network 'stack2')" in text
    assert "hidden (int [1, 64], default 4): hidden channels" in text
    lf = _lf()
    method = create("stack2", weights=nets["stack2"])
    assert type(method) is StackMethod
    from lfbench.utils.threads import torch_threads

    with torch_threads(1):  # as the reference runs
        disparity = method.run(lf).disparity
    np.testing.assert_array_equal(disparity, _reference(nets["stack2"], lf)[0])
    assert get_trainable("stack2").method_name == "stack2"


def test_parameters_given_must_agree_with_the_weights(nets):
    lf = _lf()
    assert create("stack", weights=nets["stack"], hidden=4).available_for(lf) is None
    with pytest.raises(SpecError, match=r"stack: hidden=6 \(checkpoint: 4\) conflicts with the weights"):
        create("stack", weights=nets["stack"], hidden=6).available_for(lf)
    with pytest.raises(SpecError, match=r"stack:hidden: must be in \[1, 64\], got 0"):
        create_from_spec(f"stack:weights={nets['stack']},hidden=0")
    with pytest.raises(SpecError, match="stack:hidden: expected int, got '4.5'"):
        create_from_spec(f"stack:weights={nets['stack']},hidden=4.5")


def test_foreign_files_are_named_in_one_line(nets, tmp_path):
    lf = _lf()
    cases = {"w.json": (b'{"state_dict": 1}', "a JSON file, not a torch checkpoint"),
             "w.h5": (b"\x89HDF\r\n\x1a\n" + bytes(64), "an HDF5 file (a Keras checkpoint?"),
             "w.txt": (b"weights\n", "a text file, not a torch checkpoint"),
             "w.zip": (None, "a zip archive, not a readable torch checkpoint"),
             "empty.pt": (b"", "an empty file, not a torch checkpoint")}
    for name, (data, message) in cases.items():
        path = tmp_path / name
        if data is None:
            import zipfile

            with zipfile.ZipFile(path, "w") as z:
                z.writestr("a.txt", "x")
        else:
            path.write_bytes(data)
        with pytest.raises(DataError) as info:
            create("stack", weights=path).available_for(lf)
        text = str(info.value)
        assert text.startswith(f"{path}: ") and message in text and "\n" not in text, text
        assert "weights_only" not in text  # torch's advice (to load with weights_only=False) is never passed on
    pickled = tmp_path / "pickled.pt"
    torch.save({"state_dict": {}, "config": {}, "thing": Path("x")}, pickled)  # a Python object: not weights-only
    with pytest.raises(DataError, match="holds Python objects beyond tensors and plain values") as info:
        create("stack", weights=pickled).available_for(lf)
    assert "weights_only" not in str(info.value)
    with pytest.raises(DataError, match=r"whole.pt: a whole checkpoint, not stack \(run it as whole:weights=...\)"):
        create("stack", weights=nets["whole"]).available_for(lf)
    resume = tmp_path / "checkpoint.pt"
    torch.save({"format": "lfbench.train.checkpoint", "model": {}}, resume)
    with pytest.raises(DataError, match="a training checkpoint .* give the run's final.pt"):
        create("stack", weights=resume).available_for(lf)
    # the same network under another name (SubFocal and LFattNet share theirs) loads the other's weights
    assert create("stack2", weights=nets["stack"]).run(lf).disparity.shape == (20, 20)


def test_results_are_keyed_by_the_weights_content_not_their_path(nets, tmp_path, monkeypatch):
    """The same weights named by a relative and by an absolute path give records that compare equal;
    the path is kept in results.json as provenance."""
    scene = HCIScene(write_scene(tmp_path / "data", "alpha", size=32))
    moved = tmp_path / "elsewhere" / "copy.pt"
    moved.parent.mkdir()
    moved.write_bytes(nets["stack"].read_bytes())
    monkeypatch.chdir(tmp_path)
    runs = {}
    for tag, spec in (("rel", "stack:weights=stack.pt"), ("abs", f"stack:weights={nets['stack']}"),
                      ("moved", f"stack:weights={moved}")):
        method = create_from_spec(spec)
        runs[tag] = evaluate_to_folder([method], [scene], tmp_path / tag, writers=(), progress=False,
                                       meta={"methods": {method.label: method.provenance()}})
    labels = {tag: set(r.methods) for tag, r in runs.items()}
    digest = __import__("hashlib").sha256(nets["stack"].read_bytes()).hexdigest()
    assert labels["rel"] == labels["abs"] == labels["moved"] == {f"stack:weights=sha256:{digest[:12]}"}
    from lfbench.runs.regress import make_golden

    make_golden(runs["rel"], 0.0, tmp_path / "golden.json")
    for tag in ("abs", "moved"):
        result = check(read_golden(tmp_path / "golden.json"), Results.read(tmp_path / tag / "results.json"))
        assert result.passed and result.compared == 5 and not result.findings
    saved = json.loads((tmp_path / "moved" / "results.json").read_text())["meta"]["methods"]
    (entry,) = saved.values()
    assert entry["weights"] == {"path": str(moved), "sha256": digest} and entry["spec"] == f"stack:weights={moved}"
    # a user-given label names the records instead
    named = create_from_spec("stack:weights=stack.pt").with_label("mine")
    assert named.label == "mine"


def test_two_class_records_are_keyed_by_the_weights_content(nets, tmp_path, capsys):
    """Issue 32.3: a plugin's own method (the two-class style) named its records by the weights' path, so a
    moved weights file broke the gate (every record missing and new). Its weights are named by content too:
    results with the file at A and then moved to B compare equal in ``lfbench regress``."""
    from helpers import run_cli

    scene = HCIScene(write_scene(tmp_path / "data", "alpha", size=32))
    a = tmp_path / "a" / "w.pt"
    a.parent.mkdir()
    a.write_bytes(nets["stack2"].read_bytes())
    digest = __import__("hashlib").sha256(a.read_bytes()).hexdigest()
    method = create_from_spec(f"stack2:weights={a}")
    assert type(method) is StackMethod and method.label == f"stack2:weights=sha256:{digest[:12]}"
    before = evaluate_to_folder([method], [scene], tmp_path / "at_a", writers=(), progress=False,
                                meta={"methods": {method.label: method.provenance()}})
    b = tmp_path / "b" / "moved.pt"
    b.parent.mkdir()
    a.rename(b)
    method = create_from_spec(f"stack2:weights={b}")
    evaluate_to_folder([method], [scene], tmp_path / "at_b", writers=(), progress=False,
                       meta={"methods": {method.label: method.provenance()}})
    from lfbench.runs.regress import make_golden

    make_golden(before, 0.0, tmp_path / "golden.json")
    rc, out, err = run_cli(capsys, "regress", tmp_path / "golden.json", tmp_path / "at_b" / "results.json",
                           "--fail-on-new")
    assert rc == 0, out + err
    assert "OK: 5 compared, 0 regressions" in out + err and "NEW" not in out + err and "MISSING" not in out + err
    saved = json.loads((tmp_path / "at_b" / "results.json").read_text())["meta"]["methods"]
    assert saved[method.label]["weights"] == {"path": str(b), "sha256": digest}  # the path stays as provenance


@pytest.mark.parametrize(("head", "size", "message"), [
    (b"PK\x03\x04", 50 * 1024**3, "weights file of 50.0 GiB, larger than the 8 GiB lfbench reads"),
    (b"\x80\x02", 50 * 1024**3, "weights file of 50.0 GiB, larger than the 8 GiB lfbench reads"),
    (b"PK\x03\x04", 7 * 1024**3, "a damaged or incomplete file, not a readable torch checkpoint"),
    (b"{", 7 * 1024**3, "a JSON file, not a torch checkpoint"),
])
def test_a_huge_or_foreign_weights_file_is_refused_before_it_is_hashed(nets, tmp_path, monkeypatch, head, size,
                                                                       message):
    """NAME:weights=FILE names the method by the file's hash: the file's kind and size are checked first, from
    bounded reads, so a sparse file of 50 GB (or 7 GB of zeros behind a zip header) is one line, and is never
    read whole (the hash function fails if called)."""
    import lfbench.method.base as base
    import lfbench.utils.readfile as readfile

    path = tmp_path / "huge.pt"
    with open(path, "wb") as f:
        f.write(head)
        f.truncate(size)  # sparse: no disk used
    read = []
    real_read = readfile.os.read

    def counting_read(fd, n):
        data = real_read(fd, n)
        read.append(len(data))
        return data

    def no_hash(*args, **kwargs):
        raise AssertionError("the file was hashed before it was checked")

    method = create_from_spec(f"stack:weights={path}")
    with monkeypatch.context() as patch:
        patch.setattr(base, "file_sha256", no_hash)
        patch.setattr(readfile.os, "read", counting_read)
        with pytest.raises(DataError) as info:
            method.label  # noqa: B018 - the label hashes the weights
        assert str(info.value) == f"{path}: {message}"
        with pytest.raises(DataError, match="not a readable torch checkpoint|larger than|not a torch checkpoint"):
            method.provenance()
    assert sum(read) < 1024**2  # bounded reads only
    # real weights are still named by their content
    assert create_from_spec(f"stack:weights={nets['stack']}").label.startswith("stack:weights=sha256:")
