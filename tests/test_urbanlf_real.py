"""The released UrbanLF-Syn, for whoever has it (LFBENCH_URBANLF_ROOT = the folder holding train/ val/ test/;
skipped otherwise, as on this project's machines). Its sources do not say which index of ``u_v.png`` is the
row nor the sign of its disparity (docs/datasets.md); these tests settle both from the data's own ground truth
and fail, naming the reading the data follows, if the ``urbanlf-syn`` adapter's assumption is wrong."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import run_cli

from lfbench.data.dataset import detect_dataset
from lfbench.data.urbanlf import UrbanLFSyn

SAMPLES = 3  # of the val split: each takes ~10 s at 640x480 on 2 cores


@pytest.fixture(scope="module")
def val_samples(urbanlf_root):
    assert detect_dataset(urbanlf_root) is UrbanLFSyn
    scenes = [s for s in UrbanLFSyn.open(urbanlf_root).by_category("val") if s.has_gt()]
    if not scenes:
        pytest.skip(f"{urbanlf_root} has no val split with ground truth")
    return scenes[:SAMPLES]


def test_the_released_layout_opens_at_its_size(val_samples):
    scene = val_samples[0]
    assert scene.angular_size == (9, 9) and scene.spatial_size == (480, 640)
    gt = scene.gt_disparity()
    assert gt.shape == (480, 640) and np.isfinite(gt).all()
    assert -0.5 <= float(gt.min()) and float(gt.max()) <= 1.6  # the released range [-0.47, 1.55] px


def test_the_released_data_agrees_with_the_adapters_reading(urbanlf_root, val_samples, capsys):
    names = ",".join(s.name for s in val_samples)
    rc, out, _ = run_cli(capsys, "check-dataset", str(urbanlf_root), "--scenes", names, "--details", "--no-progress")
    assert rc == 0 and f"{len(val_samples)} of {len(val_samples)} scenes with ground truth agree" in out, out


def test_the_plane_sweep_beats_the_zero_map_on_a_released_sample(urbanlf_root, val_samples, tmp_path, capsys):
    rc, _, err = run_cli(capsys, "evaluate", "--data", str(urbanlf_root), "--scenes", val_samples[0].name,
                         "--method", "planesweep", "--method", "constant", "--out", str(tmp_path / "run"),
                         "--no-progress")
    assert rc == 0, err
    import json

    records = json.loads((tmp_path / "run" / "results.json").read_text())["records"]
    bad = {r["method"].split(":")[0]: r["value"] for r in records if r["metric"] == "badpix_0.07"}
    assert bad["planesweep"] < bad["constant"]
