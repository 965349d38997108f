"""A dataset plugin of a layout lfbench does not know (tests/npy7_plugin.py: 7x7 views stored as one .npy per
scene, its own ground truth and protocol), installed through the ``lfbench.datasets`` entry-point group, goes
through ``datasets``, ``check-dataset``, ``evaluate``, ``train`` and ``ablate`` (timed at its own 7x7 views) with
nothing but the public adapter contract (issue 38)."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, install_dataset_plugin, run_cli, shifted_views
from npy7_plugin import ANGULAR, NPY7_PROTOCOL, Npy7Scene, write_npy7_scene

from lfbench.data.dataset import DatasetProtocol

SIZE = (24, 32)  # (H, W)
DISPARITIES = {"train": (1, -1, 1), "val": (-1,)}  # px per view step, integer: the views are exact shifts


@pytest.fixture
def npy7(tmp_path, monkeypatch) -> Path:
    """The plugin installed as a distribution with an ``lfbench.datasets`` entry point, and a data root of it."""
    install_dataset_plugin(tmp_path / "site", monkeypatch, "lfbench-npy7-test", {"npy7": "npy7_plugin:Npy7Dataset"})
    root = tmp_path / "npy7"
    rng = np.random.default_rng(0)
    h, w = SIZE
    for category, disparities in DISPARITIES.items():
        for i, d in enumerate(disparities):
            centre = rng.integers(0, 256, size=(h, w, 3), dtype=np.uint8)
            write_npy7_scene(root, f"{category}{i}", category, shifted_views(centre, d, ANGULAR),
                             np.full((h, w), float(d), np.float32))
    return root


def test_the_plugin_is_listed_detected_and_its_views_are_read_through_the_adapter(npy7, capsys):
    from lfbench.data.dataset import open_dataset
    from lfbench.training.data import load_scene_data

    rc, out, err = run_cli(capsys, "datasets")
    assert rc == 0, err
    assert "npy7" in out and "4 px border" in out
    dataset, bench = open_dataset(npy7)
    assert dataset.name == "npy7" and sorted(bench.names) == ["train0", "train1", "train2", "val0"]
    scene = bench.select(["train0"])[0]
    stored = np.load(scene.path)  # (7, 7, H, W, 3) uint8
    data = load_scene_data(scene)  # what training keeps: view k = row k // 7, column k % 7
    assert data.angular == (7, 7) and data.rgb.shape == (*SIZE, 49, 3)
    np.testing.assert_array_equal(data.rgb[:, :, 7 * 2 + 5], stored[2, 5])
    np.testing.assert_array_equal(scene.center_view(), stored[3, 3] / np.float32(255.0))
    gray = scene.gray_views()
    assert gray.shape == (7, 7, *SIZE)
    scene.release_views()
    assert "_views" not in scene.__dict__ and "_gray" not in scene.__dict__


def test_check_dataset_and_evaluate_score_it_by_its_protocol(npy7, tmp_path, capsys):
    rc, out, err = run_cli(capsys, "check-dataset", npy7)
    assert rc == 0, err + out
    rc, out, err = run_cli(capsys, "evaluate", "--data", npy7, "--method", "planesweep", "--out", tmp_path / "ev",
                           "--scenes", "val")
    assert rc == 0, err
    results = json.loads((tmp_path / "ev" / "results.json").read_text())
    assert results["meta"]["dataset"] == "npy7"
    scored = {r["metric"]: r["value"] for r in results["records"] if r["scene"] == "val0"}
    assert set(scored) == set(NPY7_PROTOCOL.metrics)  # the protocol's metrics, no other
    # an exact integer shift of a random texture: the plane sweep finds d = -1 on every pixel inside the 4 px border
    assert scored["badpix_0.07"] == 0.0 and 0.0 <= scored["mse_x100"] < 0.01


TRAIN = """
seed = 3
[data]
roots = ["{root}"]
train = ["train"]
validation = ["val"]
patch = 16
strides = [1]
stride_weights = [1]
texture = 0.0
[augment]
enabled = false
[model]
width = 2
angular = 7
d_min = -2.0
d_max = 2.0
interval = 1.0
[training]
batch_size = 1
device = "cpu"
threads = 1
checkpoint_every = 2
log_every = 1
prefetch = 0
[validation]
every = 2
border = 4
max_size = 0
[[stages]]
name = "l1"
loss = "l1"
lr = 1e-3
steps = 2
"""


@pytest.mark.slow
def test_train_on_it_then_evaluate_the_weights_on_its_7x7_views(npy7, tmp_path, capsys):
    config = tmp_path / "train.toml"
    config.write_text(TRAIN.format(root=npy7))
    rc, out, err = run_cli(capsys, "train", config, "--out", tmp_path / "run")
    assert rc == 0, err
    weights = tmp_path / "run" / "final.pt"
    rc, out, err = run_cli(capsys, "evaluate", "--data", npy7, "--method", f"subfocal:weights={weights}",
                           "--scenes", "val", "--out", tmp_path / "ev")
    assert rc == 0, err
    records = json.loads((tmp_path / "ev" / "results.json").read_text())["records"]
    assert {r["scene"] for r in records} == {"val0"} and {r["metric"] for r in records} == set(NPY7_PROTOCOL.metrics)
    assert all(np.isfinite(r["value"]) for r in records)


ABLATION = """title = "npy7"
table = "none"
base = "train.toml"
[[grid]]
width = [2]
[budget]
threads = 1
[evaluation]
data = "{root}"
scenes = ["val"]
time_size = 16
time_repeats = 1
time_warmup = 0
threads = 1
device = "cpu"
"""


def _ablation(tmp_path: Path, root: Path, angular: int) -> Path:
    """An ablation of one cell whose network takes ``angular`` x ``angular`` views, scored on the plugin's scenes."""
    (tmp_path / "train.toml").write_text(TRAIN.format(root=root).replace("angular = 7", f"angular = {angular}"))
    spec = tmp_path / "ablate.toml"
    spec.write_text(ABLATION.format(root=root))
    return spec


@pytest.mark.slow
def test_ablate_trains_scores_and_times_cells_at_its_angular_size(npy7, tmp_path, capsys):
    spec = _ablation(tmp_path, npy7, ANGULAR)
    rc, out, err = run_cli(capsys, "ablate", spec, "--out", tmp_path / "abl")
    assert rc == 0, err
    timing = json.loads(next((tmp_path / "abl" / "cells").glob("*/timing.json")).read_text())
    assert timing["time_angular"] == [7, 7] and timing["key"]["angular"] == [7, 7] and timing["test_s"] > 0


def test_ablate_refuses_a_network_that_cannot_take_the_scenes_before_training(npy7, tmp_path, capsys):
    spec = _ablation(tmp_path, npy7, 9)  # a 9x9 network, 7x7 evaluation scenes
    rc, out, err = run_cli(capsys, "ablate", spec, "--out", tmp_path / "abl")
    assert rc == 2 and "takes 9x9 views, the evaluation scenes have 7x7" in err, err
    assert not list((tmp_path / "abl").glob("cells/*/checkpoint.pt")) and not (tmp_path / "abl" / "data").exists()


def test_a_scene_pickles_as_its_file(npy7):
    import pickle

    scene = Npy7Scene(next(npy7.glob("val/*.views.npy")), "val")
    scene.gray_views()
    again = pickle.loads(pickle.dumps(scene))
    assert "_views" not in again.__dict__ and again.spatial_size == SIZE and again.name == "val0"


# -- issue 38: the protocol everywhere (training validation) and bad input as one line -----------------------------

#: A protocol of its own: a 6 px border, BadPix 0.05 / 0.2 and MSE x100 (no BadPix of the paper's three).
OWN_PROTOCOL = DatasetProtocol(border_px=6, metrics=("badpix_0.05", "badpix_0.2", "mse_x100"),
                               disparity_range=(-2.0, 2.0), angular_size=(ANGULAR, ANGULAR))


@pytest.fixture
def own_protocol(npy7, monkeypatch) -> Path:
    """The plugin's data root, its adapter declaring :data:`OWN_PROTOCOL`."""
    from npy7_plugin import Npy7Dataset

    monkeypatch.setattr(Npy7Dataset, "protocol", OWN_PROTOCOL)
    return npy7


def _config(root: Path, validation: str = "") -> str:
    """TRAIN without its [validation] border: ``validation``, lines of that section instead."""
    return TRAIN.format(root=root).replace("border = 4\n", validation)


def test_validation_takes_the_border_and_badpix_of_the_training_datas_protocol(own_protocol, tmp_path):
    from lfbench.training.config import TrainConfig

    cfg = TrainConfig.from_dict(tomllib.loads(_config(own_protocol)))
    # the protocol's border and its first BadPix (table order: as the protocol lists them); recorded as such
    assert (cfg.validation.border, cfg.validation.threshold) == (6, 0.05)
    assert cfg.to_dict()["validation"] == {"every": 2, "max_size": 0, "border": 6, "threshold": 0.05}
    explicit = TrainConfig.from_dict(tomllib.loads(_config(own_protocol, "border = 3\nthreshold = 0.1\n")))
    assert (explicit.validation.border, explicit.validation.threshold) == (3, 0.1)  # a value of the config wins


def test_validation_takes_the_scorer_of_the_training_datas_protocol(npy7, monkeypatch, capsys):
    """A protocol scored by the paper author's scorer (UrbanLF-Syn's) is validated by it, recorded in the config;
    a config's own scorer wins, also where it sets border and threshold; an unknown one is one line."""
    import dataclasses

    from npy7_plugin import Npy7Dataset

    from lfbench.training.config import TrainConfig
    from lfbench.utils.errors import SpecError

    monkeypatch.setattr(Npy7Dataset, "protocol", dataclasses.replace(OWN_PROTOCOL, scorer="paper-author"))
    cfg = TrainConfig.from_dict(tomllib.loads(_config(npy7)))
    assert cfg.validation.scorer == "paper-author"
    assert cfg.to_dict()["validation"]["scorer"] == "paper-author"
    assert TrainConfig.from_dict(cfg.to_dict()) == cfg
    fixed = TrainConfig.from_dict(tomllib.loads(_config(npy7, "border = 3\nthreshold = 0.1\n")))
    assert fixed.validation.scorer == "paper-author"  # read from the data although border and threshold are set
    own = TrainConfig.from_dict(tomllib.loads(_config(npy7, 'scorer = "lfbench"\n')))
    assert own.validation.scorer == "lfbench" and own.to_dict()["validation"]["scorer"] == "lfbench"
    with pytest.raises(SpecError, match=r"validation.scorer.*must be one of lfbench, paper-author, got 'toolkit'"):
        TrainConfig.from_dict(tomllib.loads(_config(npy7, 'scorer = "toolkit"\n')))


def test_hci_validation_keeps_its_border_and_badpix(tmp_path):
    from helpers import write_scene

    from lfbench.training.config import TrainConfig

    write_scene(tmp_path / "hci", "val", "stratified")
    raw = tomllib.loads(_config(tmp_path / "hci"))
    cfg = TrainConfig.from_dict(raw)
    assert (cfg.validation.border, cfg.validation.threshold) == (15, 0.07)
    # the same config dict as when 15 and 0.07 were the declared defaults: checkpoints resume, cells keep fingerprints
    assert cfg.to_dict()["validation"] == {"every": 2, "max_size": 0, "border": 15, "threshold": 0.07}
    assert cfg.validation.scorer is None  # lfbench's own, left unrecorded: the config dict stays as it was
    raw["data"]["roots"] = [str(tmp_path / "absent")]  # a root not there yet: the benchmark's, refused when run
    assert TrainConfig.from_dict(raw).validation.border == 15


def test_training_validation_scores_by_the_protocol(own_protocol, tmp_path, capsys):
    from lfbench.training.curves import _validation_labels, read_metrics

    config = tmp_path / "train.toml"
    config.write_text(_config(own_protocol).replace("steps = 2", "steps = 1").replace("every = 2", "every = 1"))
    rc, out, err = run_cli(capsys, "train", config, "--out", tmp_path / "run", "--no-progress")
    assert rc == 0, err
    vals = [e for e in read_metrics(tmp_path / "run" / "metrics.jsonl") if e["event"] == "validation"]
    h, w = SIZE
    assert [(v["pixels"], v["threshold"]) for v in vals] == [((h - 12) * (w - 12), 0.05)]  # 12 x 20 px: 6 px border
    assert _validation_labels(vals) == ("BadPix 0.05 (%)", "MSE x100")  # the learning curve's axis label
    assert "[validation] step 1: BadPix(0.05) " in out + err


class _AnySizeScene(Npy7Scene):
    """The plugin's scene with its adapter's own checks turned off: any angular size (the file's), float views as
    stored (a NaN kept)."""

    def __init__(self, path: str | Path, category: str = "other") -> None:
        self.path = Path(path)
        self.name = self.path.name.removesuffix(".views.npy")
        self.category = category
        header = np.load(self.path, mmap_mode="r")
        self._angular, self._shape = tuple(header.shape[:2]), tuple(header.shape[2:4])

    @property
    def angular_size(self) -> tuple[int, int]:
        return self._angular

    def load_views(self) -> np.ndarray:
        views = np.load(self.path)
        return views if views.dtype == np.float32 else views.astype(np.float32) / np.float32(255.0)


@pytest.fixture
def any_size(npy7, monkeypatch) -> Path:
    """The plugin's data root read with :class:`_AnySizeScene`."""
    from npy7_plugin import Npy7Dataset

    from lfbench.data.scene import Benchmark

    def open_any(cls, root: Path) -> Benchmark:
        return Benchmark(root=root, scenes=tuple(_AnySizeScene(p, p.parent.name)
                                                  for p in sorted(Path(root).glob("*/*.views.npy"))))

    monkeypatch.setattr(Npy7Dataset, "open", classmethod(open_any))
    return npy7


def _add_scene(root: Path, name: str, category: str, angular: int = 5, gt: bool = True, dtype=np.uint8) -> Path:
    """A scene of ``angular`` x ``angular`` views written beside the others (without its .disp.npy unless ``gt``)."""
    h, w = SIZE
    centre = np.random.default_rng(1).integers(0, 256, size=(h, w, 3), dtype=np.uint8)
    views = shifted_views(centre, 1, angular)
    path = write_npy7_scene(root, name, category, views, np.full((h, w), 1.0, np.float32))
    if dtype != np.uint8:
        np.save(path, (views / 255.0).astype(dtype))
    if not gt:
        path.with_name(f"{name}.disp.npy").unlink()
    return path


def test_train_refuses_scenes_of_mixed_angular_size_naming_the_file_before_writing(any_size, tmp_path, capsys):
    path = _add_scene(any_size, "v5", "train")  # 5x5 among the 7x7 training scenes
    config = tmp_path / "train.toml"
    config.write_text(TRAIN.format(root=any_size))
    rc, out, err = run_cli(capsys, "train", config, "--out", tmp_path / "run")
    line = assert_one_error_line(rc, err, str(path), "has 5x5 views", "'train0'", "7x7")
    assert "training scene 'v5' has 5x5 views, the run's first scene 'train0' 7x7" in line
    assert not (tmp_path / "run").exists()  # nothing written: no command.txt, config.toml, metrics.jsonl, lock


def test_evaluate_warns_of_a_scene_without_ground_truth_and_scores_the_others(any_size, tmp_path, capsys):
    path = _add_scene(any_size, "nogt", "val", angular=7, gt=False)
    rc, out, err = run_cli(capsys, "evaluate", "--data", any_size, "--method", "planesweep", "--out", tmp_path / "ev",
                           "--scenes", "val", "--no-progress")
    assert rc == 0, err
    assert (f"warning: 1 selected scene(s) have no ground truth and are not scored: nogt (first: {path})"
            in err.splitlines())
    records = json.loads((tmp_path / "ev" / "results.json").read_text())["records"]
    assert {r["scene"] for r in records} == {"val0"}


def test_evaluate_refuses_a_scene_of_another_angular_size_than_the_protocols(any_size, tmp_path, capsys):
    path = _add_scene(any_size, "small", "val")  # 5x5 views, the protocol's are 7x7
    rc, out, err = run_cli(capsys, "evaluate", "--data", any_size, "--method", "planesweep", "--out", tmp_path / "ev",
                           "--scenes", "val", "--no-progress")
    line = assert_one_error_line(rc, err, str(path))
    assert "scene 'small' has 5x5 views, its dataset's protocol 7x7: it cannot be scored by that protocol" in line
    assert not (tmp_path / "ev").exists()


def test_evaluate_names_the_file_of_views_holding_nan(any_size, tmp_path, capsys):
    path = _add_scene(any_size, "holes", "val", angular=7, dtype=np.float32)
    views = np.load(path)
    views[3, 3, 0, 0, 0] = np.nan
    np.save(path, views)
    rc, out, err = run_cli(capsys, "evaluate", "--data", any_size, "--method", "planesweep", "--out", tmp_path / "ev",
                           "--scenes", "holes", "--no-progress")
    line = assert_one_error_line(rc, err, str(path))
    assert line.endswith(f"{path}: the views of scene 'holes' hold NaN or infinite values"), line


def test_train_refuses_7x7_scenes_beside_a_synthetic_set_before_generating_it(npy7, tmp_path, capsys):
    config = tmp_path / "train.toml"
    config.write_text(TRAIN.format(root=npy7).replace('validation = ["val"]', 'validation = ["synthetic"]')
                      .replace('train = ["train"]', 'train = ["train0"]')  # (HCI's split "train" is another)
                      + '[[data.synthetic]]\ncategory = "synthetic"\nsize = 32\nscenes = 1\n')
    rc, out, err = run_cli(capsys, "train", config, "--out", tmp_path / "run")
    line = assert_one_error_line(rc, err, "has 9x9 views, the run's first scene 'train0' 7x7")
    assert str(tmp_path / "run" / "data" / "synthetic") in line
    assert not (tmp_path / "run").exists()  # nothing generated, nothing written
