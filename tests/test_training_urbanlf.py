"""Training on UrbanLF-Syn through the dataset seam (issue 30 item 3): synthetic sets in the urbanlf-syn layout
(non-square), roots opened by their detected layout or data.dataset, the trained checkpoint evaluated beside the
plane sweep; SubFocal takes the dataset's disparity range only where no weights fix its grid."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lfbench.data.dataset import method_range_params
from lfbench.data.synth_urbanlf import write_urbanlf
from lfbench.data.urbanlf import URBANLF_PROTOCOL, UrbanLFSyn
from lfbench.method.registry import create_from_spec
from lfbench.training.config import TrainConfig
from lfbench.training.scenes import check_data, discover
from lfbench.utils.errors import DataError, SpecError

H, W = 40, 56  # non-square, as UrbanLF-Syn's 480x640
URBAN = URBANLF_PROTOCOL.disparity_range


def urban_config(**data) -> TrainConfig:
    sets = [{"category": "utrain", "layout": "urbanlf-syn", "seed": 3, "size": H, "width": W, "scenes": 2},
            {"category": "uval", "layout": "urbanlf-syn", "seed": 4, "size": H, "width": W, "scenes": 1}]
    raw = {
        "seed": 7,
        "data": {"synthetic": sets, "train": ["utrain"], "validation": ["uval"], "patch": 16, "strides": [1, 2],
                 "stride_weights": [8, 6], **data},
        "model": {"width": 4, "d_min": URBAN[0], "d_max": URBAN[1], "interval": 0.1},
        "training": {"batch_size": 1, "threads": 1, "checkpoint_every": 10, "log_every": 10, "prefetch": 1},
        "validation": {"every": 0, "max_size": 0, "border": 4},
        "stages": [{"name": "l1", "loss": "l1", "lr": 1e-3, "steps": 3},
                   {"name": "uafl", "loss": "uafl", "beta": 0.1, "lr": 1e-4, "steps": 1}],
    }
    return TrainConfig.from_dict(raw)


@pytest.fixture(scope="module")
def urban_run(tmp_path_factory):
    from lfbench.training.loop import train

    out = tmp_path_factory.mktemp("urban") / "out"
    cfg = urban_config()
    check_data(cfg, out / "data")  # the planned non-square sets pass the validation-area check
    return cfg, out, train(cfg, out, progress=False, command="test")


def test_synthetic_sets_are_written_in_the_urbanlf_layout_with_distinct_names(urban_run):
    cfg, out, _ = urban_run
    data = out / "data"
    assert UrbanLFSyn.matches(data / "utrain") and not (data / "utrain" / "synth_3_0").exists()
    bench = discover(cfg, data)
    assert sorted(s.name for s in bench.scenes) == sorted(n for spec in cfg.data.synthetic for n in spec.scene_names())
    assert {s.spatial_size for s in bench.scenes} == {(H, W)}
    assert all((s.path / "5_5.png").is_file() for s in bench.scenes)


def test_a_trained_urbanlf_checkpoint_evaluates_on_its_grid_beside_the_plane_sweep(urban_run):
    cfg, out, result = urban_run
    assert Path(result["final"]).is_file()
    scene = UrbanLFSyn.open(out / "data" / "uval").scenes[0]
    hook = method_range_params(URBAN)
    net = create_from_spec(f"subfocal:weights={out / 'final.pt'}", {"device": "cpu"}, hook)
    sweep = create_from_spec("planesweep", {"device": "cpu"}, hook)
    assert "d_min" not in net.params  # the checkpoint's grid decides: the dataset's range is not laid on top
    pred, base = net.run(scene).disparity, sweep.run(scene).disparity
    gt = scene.gt_disparity()
    assert pred.shape == base.shape == gt.shape == (H, W)
    assert np.isfinite(pred).all() and np.isfinite(base).all()
    # an expectation over the checkpoint's candidates: inside UrbanLF-Syn's grid, not HCI's [-4, 4]
    assert URBAN[0] - 1e-5 <= pred.min() and pred.max() <= URBAN[1] + 1e-5
    assert sweep.params["d_min"] == URBAN[0] and sweep.params["d_max"] >= URBAN[1]
    assert URBAN[0] <= base.min() and base.max() <= sweep.params["d_max"]  # the sweep beside it: same range
    # scored as evaluate scores them (the dataset's border): finite numbers for both, on the same pixels
    b = URBANLF_PROTOCOL.border_px // 4  # the 15 px border scaled down to this 40x56 scene
    errors = [float(np.mean((p[b:-b, b:-b] - gt[b:-b, b:-b]) ** 2)) for p in (pred, base)]
    assert all(np.isfinite(errors)) and all(e > 0 for e in errors)


def test_subfocal_takes_the_dataset_range_only_where_no_weights_fix_its_grid(tmp_path):
    hook = method_range_params(URBAN)
    shipped = create_from_spec("subfocal:width=16", {"device": "cpu"}, hook)  # the shipped HCI checkpoint loads
    assert "d_min" not in shipped.params and shipped.weights_path == shipped.shipped_weights
    free = create_from_spec("subfocal:width=8", {"device": "cpu"}, hook)  # no weights of this architecture
    assert free.weights_path is None
    assert (free.params["d_min"], free.params["d_max"]) == (URBAN[0], 2.0)  # 0.5 px grid up to >= 1.6
    spec = create_from_spec("subfocal:width=8,d_min=-1,d_max=1", {"device": "cpu"}, hook)
    assert (spec.params["d_min"], spec.params["d_max"]) == (-1.0, 1.0)  # the spec wins


def test_data_dataset_forces_an_adapter_and_bad_names_are_config_errors(tmp_path):
    write_urbanlf(tmp_path / "urban", seed=1, width=W, height=H, scenes=1, split="train")
    base = {"roots": [str(tmp_path / "urban")], "train": ["train"], "synthetic": []}
    cfg = urban_config(**base, validation=[])
    assert [s.name for s in discover(cfg, tmp_path / "data").scenes] == ["Image1"]  # detected
    with pytest.raises(DataError, match="not laid out as dataset 'hci'"):
        discover(urban_config(**base, validation=[], dataset="hci"), tmp_path / "data")
    with pytest.raises(SpecError, match="dataset"):
        urban_config(**base, validation=[], dataset="nope")
    with pytest.raises(SpecError, match="width"):
        urban_config(synthetic=[{"category": "s", "size": 32, "width": 48}])


def test_the_smoke_config_reads_as_the_urbanlf_layout():
    cfg = TrainConfig.from_toml(Path(__file__).resolve().parents[1] / "configs" / "subfocal_urbanlf_cpu_smoke.toml")
    assert {s.layout for s in cfg.data.synthetic} == {"urbanlf-syn"}
    assert (cfg.model["d_min"], cfg.model["d_max"], cfg.model["interval"]) == (*URBAN, 0.1)


def test_the_new_keys_leave_the_dicts_and_fingerprints_of_older_configs_alone():
    old = TrainConfig.from_dict({"data": {"synthetic": [{"category": "s"}]}, "stages": [{"loss": "l1", "steps": 1}]})
    d = old.to_dict()["data"]
    assert "dataset" not in d and not {"width", "layout"} & set(d["synthetic"][0])
    new = urban_config().to_dict()["data"]["synthetic"][0]
    assert (new["layout"], new["width"]) == ("urbanlf-syn", W)
    assert TrainConfig.from_dict(urban_config().to_dict()) == urban_config()


def test_a_plugin_network_with_d_min_and_d_max_keeps_its_weights_grid():
    from types import SimpleNamespace

    from lfbench.method.network_method import NetworkMethod
    from lfbench.method.params import Param

    params = {k: Param(k, float, v, "") for k, v in (("d_min", -4.0), ("d_max", 4.0))}
    hook = method_range_params(URBAN)
    plain = SimpleNamespace(name="sweepish", params=params, method_class=None)
    network = SimpleNamespace(name="netish", params=params, method_class=NetworkMethod)
    assert hook(plain, {}) == {"d_min": URBAN[0], "d_max": URBAN[1]}  # a method without weights follows the data
    assert hook(network, {}) == {}  # the weights' stored config decides: a default laid over it would conflict


def test_a_root_of_no_known_layout_is_one_line_and_nothing_is_written(tmp_path):
    import subprocess
    import sys

    (tmp_path / "empty" / "train").mkdir(parents=True)
    cfg = tmp_path / "bad.toml"
    cfg.write_text(f'[data]\nroots = ["{tmp_path / "empty"}"]\n[[stages]]\nloss = "l1"\nsteps = 1\n')
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "lfbench", "train", str(cfg), "--out", str(out)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "Traceback" not in run.stderr
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "no known dataset layout" in lines[0] and str(tmp_path / "empty") in lines[0]
    assert not out.exists()


def test_validation_scores_by_the_urbanlf_protocol_with_or_without_the_data(tmp_path, monkeypatch):
    """The UrbanLF-Syn protocol's scorer (the paper author's) for validation, from the synthetic sets' layout, from a
    root named as urbanlf-syn, and from that name alone where the root is not there: the same config dict (and the
    same ablation fingerprint) on every machine."""
    assert urban_config().validation.scorer == URBANLF_PROTOCOL.scorer == "paper-author"
    repo = Path(__file__).resolve().parents[1]
    dicts = []
    for root in (None, tmp_path / "not-there"):
        if root is None:
            monkeypatch.delenv("LFBENCH_URBANLF_ROOT", raising=False)  # ${LFBENCH_URBANLF_ROOT} unset
        else:
            monkeypatch.setenv("LFBENCH_URBANLF_ROOT", str(root))
        cfg = TrainConfig.from_toml(repo / "configs" / "subfocal_urbanlf.toml")
        assert cfg.validation.scorer == "paper-author"
        dicts.append(cfg.to_dict()["validation"])
    assert dicts[0] == dicts[1]
