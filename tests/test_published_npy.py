"""``published`` reads a submission's maps stored as .npy (UrbanLF outputs are) with the same bounded, validated
reads as PFM, and ``--label`` names its records (issue 38)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import assert_one_error_line, run_cli, write_scene

SIZE = 40


@pytest.fixture
def data(tmp_path):
    write_scene(tmp_path / "data", "tiny", size=SIZE)  # ground truth: the plane at disparity 1
    sub = tmp_path / "sub"
    (sub / "disp_maps").mkdir(parents=True)
    return tmp_path / "data", sub


def _evaluate(capsys, data, sub, out, *extra):
    return run_cli(capsys, "evaluate", "--data", data, "--method", f"published:path={sub}", "--out", out,
                   "--no-progress", *extra)


def test_npy_maps_are_scored_and_labelled(data, tmp_path, capsys):
    root, sub = data
    np.save(sub / "disp_maps" / "tiny.npy", np.full((SIZE, SIZE), 1.05, np.float64))  # |error| 0.05 everywhere
    rc, _, err = _evaluate(capsys, root, sub, tmp_path / "out", "--label", "mine")
    assert rc == 0, err
    records = json.loads((tmp_path / "out" / "results.json").read_text())["records"]
    assert {r["method"] for r in records} == {"mine"}
    value = {r["metric"]: r["value"] for r in records}
    assert value["badpix_0.07"] == 0.0 and value["badpix_0.03"] == 100.0
    assert value["mse_x100"] == pytest.approx(100 * np.float32(1.05 - 1.0) ** 2, rel=1e-5)


@pytest.mark.parametrize(("array", "problem"), [
    (np.ones((SIZE, SIZE, 2), np.float32), "prediction must be a 2-D (H, W) array, got shape (40, 40, 2)"),
    (np.ones((SIZE, SIZE), np.int32), "prediction must hold floating-point disparities, got int32"),
    (np.ones((SIZE + 1, SIZE), np.float32), "prediction is 40x41 px (W x H), larger than the scene's 40x40"),
    (np.array([{"a": 1}], dtype=object), "cannot read .npy: it holds Python objects"),
])
def test_bad_npy_maps_are_one_line(data, tmp_path, capsys, array, problem):
    root, sub = data
    np.save(sub / "disp_maps" / "tiny.npy", array, allow_pickle=array.dtype == object)
    rc, _, err = _evaluate(capsys, root, sub, tmp_path / "out")
    assert_one_error_line(rc, err, "tiny.npy", problem)
    assert not (tmp_path / "out" / "results.json").exists()


def test_a_pfm_map_wins_over_an_npy_of_the_same_scene(data, tmp_path, capsys):
    from lfbench.data.submission import find_disp_map, write_submission_map

    root, sub = data
    np.save(sub / "disp_maps" / "tiny.npy", np.zeros((SIZE, SIZE), np.float32))
    assert find_disp_map(sub, "tiny").name == "tiny.npy"
    write_submission_map(sub, "tiny", np.ones((SIZE, SIZE), np.float32), None)  # written as PFM, always
    assert find_disp_map(sub, "tiny").name == "tiny.pfm"
    rc, _, err = _evaluate(capsys, root, sub, tmp_path / "out")
    assert rc == 0, err
    records = json.loads((tmp_path / "out" / "results.json").read_text())["records"]
    assert next(r["value"] for r in records if r["metric"] == "mse_x100") == 0.0  # the PFM's exact plane
