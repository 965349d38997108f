"""Careless and hostile input to `lfbench train` (issue 12.6, 12.7): every stage validated before step 1,
a later stage fixable after earlier ones finished, one run per folder, tampered checkpoints and write
errors in one line naming the file."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest
import torch
from helpers import assert_one_error_line, run_cli, write_scene

SIZE = 24


@pytest.fixture(scope="module")
def data_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("data")
    for i in range(2):
        write_scene(root, f"plane_{i}", "additional", size=SIZE, seed=i)
    return root


def config_text(data_root: Path, stages: str, training: str = "", data: str = "") -> str:
    return (f'seed = 1\n[data]\nroots = ["{data_root}"]\npatch = 16\nstrides = [1]\nstride_weights = [1]\n{data}'
            f"[model]\nwidth = 2\ninterval = 1.0\n"
            f"[training]\nbatch_size = 1\nthreads = 1\ncheckpoint_every = 1\nlog_every = 1\nprefetch = 0\n{training}"
            f"[validation]\nevery = 0\n{stages}")


STAGE1 = '[[stages]]\nname = "l1"\nloss = "l1"\nlr = 1e-3\nsteps = 2\n'
STAGE2 = '[[stages]]\nname = "uafl"\nloss = "uafl"\nbeta = {beta}\nlr = 1e-4\nsteps = 1\n'


def write_config(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(("stages", "training", "data", "problem"), [
    (STAGE1 + STAGE2.format(beta='"x"'), "", "", "stages[1]: loss 'uafl': beta must be a finite number >= 0"),
    (STAGE1 + STAGE2.format(beta="-1"), "", "", "beta must be a finite number >= 0"),
    (STAGE1 + STAGE2.format(beta="nan"), "", "", "beta must be a finite number >= 0"),
    (STAGE1.replace("lr = 1e-3", "lr = nan"), "", "", "stages[0].lr: must be a finite number"),
    (STAGE1.replace("lr = 1e-3", "lr = inf"), "", "", "stages[0].lr: must be a finite number"),
    (STAGE1.replace("lr = 1e-3", "lr = 0"), "", "", "stages[0].lr: must be > 0, got 0.0"),
    (STAGE1.replace("steps = 2", "steps = 0"), "", "", "stages[0].steps: must be in [1, 1000000000], got 0"),
    (STAGE1 + "betas = [1.5, 0.9]\n", "", "", "stages[0].betas: expected numbers in [0, 1)"),
    (STAGE1, "", "", None),  # placeholder replaced below (batch_size)
], ids=["beta-str", "beta-neg", "beta-nan", "lr-nan", "lr-inf", "lr-0", "steps-0", "betas", "ok"])
def test_every_stage_is_validated_before_step_1(tmp_path, capsys, data_root, stages, training, data, problem):
    if problem is None:
        training, problem = "batch_size = 1000000000\n", "training.batch_size: must be in [1, 4096], got 1000000000"
        stages = STAGE1.replace("batch_size = 1\n", "")
    text = config_text(data_root, stages, data=data)
    if "batch_size = 1000000000" in training:
        text = text.replace("batch_size = 1\n", training)
    config = write_config(tmp_path, text)
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", tmp_path / "run", "--no-progress")
    assert_one_error_line(rc, err, "c.toml", problem)
    assert not (tmp_path / "run").exists()  # nothing trained, nothing written


@pytest.mark.parametrize(("category", "problem"), [("../escape", "must be a plain folder name"),
                                                   ("a/b", "must be a plain folder name")])
def test_synthetic_category_cannot_leave_the_run_folder(tmp_path, capsys, data_root, category, problem):
    data = f'[[data.synthetic]]\ncategory = "{category}"\nsize = 32\nscenes = 1\n'
    config = write_config(tmp_path, config_text(data_root, STAGE1, data=data))
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", tmp_path / "run", "--no-progress")
    assert_one_error_line(rc, err, "c.toml", "data.synthetic[0].category", problem)
    assert not (tmp_path / "escape").exists()


@pytest.fixture()
def finished_stage1(tmp_path, capsys, data_root, one_torch_thread) -> Path:
    """A run folder whose only stage (l1, 2 steps) finished: checkpoint at (stage 1, step 0)."""
    out = tmp_path / "run"
    config = write_config(tmp_path, config_text(data_root, STAGE1), "one.toml")
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", out, "--no-progress")
    assert rc == 0, err
    return out


def test_fixing_a_stage_that_has_not_started_resumes_the_finished_ones(tmp_path, capsys, data_root,
                                                                       finished_stage1):
    """Stage 1 trained, stage 2 broken (or added later): the fixed config resumes instead of being
    refused as 'config differs' (which lost stage 1)."""
    out = finished_stage1
    before = torch.load(out / "checkpoint.pt", weights_only=True)
    fixed = write_config(tmp_path, config_text(data_root, STAGE1 + STAGE2.format(beta="0.1")), "two.toml")
    rc, stdout, err = run_cli(capsys, "-q", "train", fixed, "--out", out, "--no-progress")
    assert rc == 0 and stdout + err == ""  # -q: no log lines
    rc, stdout, err = run_cli(capsys, "train", fixed, "--out", out, "--no-progress")
    assert rc == 0 and "training already complete (3 steps)" in stdout + err
    after = torch.load(out / "checkpoint.pt", weights_only=True)
    assert (before["stage"], before["global_step"]) == (1, 2) and (after["stage"], after["global_step"]) == (2, 3)
    # a change to a stage that already trained is still refused
    changed = write_config(tmp_path, config_text(data_root, STAGE1.replace("lr = 1e-3", "lr = 2e-3")
                                                 + STAGE2.format(beta="0.1")), "changed.toml")
    rc, _, err = run_cli(capsys, "-q", "train", changed, "--out", out, "--no-progress")
    assert_one_error_line(rc, err, "changed.toml", "the config differs")


def test_a_second_train_into_the_same_folder_is_refused(tmp_path, capsys, data_root):
    from lfbench.training.run_folder import run_folder_lock

    out = tmp_path / "run"
    config = write_config(tmp_path, config_text(data_root, STAGE1))
    with run_folder_lock(out):  # as a running `lfbench train` holds it
        rc, _, err = run_cli(capsys, "-q", "train", config, "--out", out, "--no-progress")
    assert_one_error_line(rc, err, str(out), "another lfbench train is running into this folder")
    assert not (out / "checkpoint.pt").exists() and not (out / "metrics.jsonl").exists()
    (tmp_path / "file").write_text("x")
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", tmp_path / "file", "--no-progress")
    assert_one_error_line(rc, err, "file", "output folder is a file")


def _tamper(out: Path, change) -> None:
    state = torch.load(out / "checkpoint.pt", weights_only=True)
    change(state)
    torch.save(state, out / "checkpoint.pt")


def _bad_optimizer(state: dict) -> None:
    state.update(stage=0, step=1, optimizer={"state": {}, "param_groups": []})


def _wrong_shape(state: dict) -> None:
    key = next(iter(state["model"]))
    state["model"][key] = torch.zeros(3, 1)


@pytest.mark.parametrize(("change", "problem"), [
    (lambda s: s.pop("stage"), "training checkpoint has no 'stage' entry"),
    (lambda s: s.update(stage="1"), "training checkpoint entry 'stage' is a str"),
    (lambda s: s.update(step=-4), "negative stage or step"),
    (lambda s: s.update(stage=7), "beyond its config's 1 stage(s)"),
    (lambda s: s.update(stage=0, step=99), "beyond the config's stages"),
    (_wrong_shape, "training checkpoint model: weights do not fit the network"),
    (lambda s: s["model"].pop(next(iter(s["model"]))), "missing 1 tensors"),
    (lambda s: s.update(rng={"python": 5}), "unusable RNG state"),
    (_bad_optimizer, "optimizer state that does not fit the model"),
    (lambda s: s.update(config=[]), "entry 'config' is a list"),
])
def test_tampered_training_checkpoint_is_one_line(tmp_path, capsys, data_root, finished_stage1, change, problem):
    out = finished_stage1
    _tamper(out, change)
    two = write_config(tmp_path, config_text(data_root, STAGE1 + STAGE2.format(beta="0.1")), "two.toml")
    rc, _, err = run_cli(capsys, "-q", "train", two, "--out", out, "--no-progress")
    assert_one_error_line(rc, err, "checkpoint.pt", problem)


def test_disk_full_while_checkpointing_is_one_line_and_keeps_the_old_checkpoint(tmp_path, capsys, data_root,
                                                                               monkeypatch, one_torch_thread):
    from lfbench.training import checkpoint

    config = write_config(tmp_path, config_text(data_root, STAGE1))
    real_save = torch.save

    def full(obj, f, *a, **kw):
        if isinstance(obj, dict) and obj.get("format") == checkpoint.CHECKPOINT_FORMAT and obj["global_step"] >= 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_save(obj, f, *a, **kw)

    monkeypatch.setattr(checkpoint.torch, "save", full)
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", tmp_path / "run", "--no-progress")
    assert_one_error_line(rc, err, "checkpoint.pt", "cannot write checkpoint: No space left on device")
    kept = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert kept["global_step"] == 1  # the last good checkpoint, not half of a new one
    assert not [p.name for p in (tmp_path / "run").iterdir() if p.name.endswith(".tmp")]


def test_final_weights_and_summary_are_one_set(tmp_path, capsys, data_root, monkeypatch, one_torch_thread):
    """final.pt and summary.json appear together (issue 20.3): a kill between them is finished by the next
    run, and a folder with final.pt but no summary.json (a kill there by an earlier version) is not taken
    for a finished run."""
    import json
    import os

    import lfbench.utils.outputs as outputs
    from lfbench.utils.errors import DataError
    from lfbench.utils.outputs import check_complete

    out = tmp_path / "run"
    config = write_config(tmp_path, config_text(data_root, STAGE1))
    real_replace = os.replace

    def killed(src, dst):  # stands for kill -9 right after final.pt was moved into the run folder
        real_replace(src, dst)
        if Path(dst) == out / "final.pt":
            raise KeyboardInterrupt

    monkeypatch.setattr(outputs.os, "replace", killed)
    rc, _, _ = run_cli(capsys, "-q", "train", config, "--out", out, "--no-progress")
    monkeypatch.setattr(outputs.os, "replace", real_replace)
    assert rc == 130 and (out / "final.pt").is_file() and not (out / "summary.json").exists()
    with pytest.raises(DataError, match="interrupted run"):
        check_complete(out)
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", out, "--no-progress")
    assert rc == 0, err
    summary = json.loads((out / "summary.json").read_text())
    weights = torch.load(out / "final.pt", weights_only=True)
    assert summary["steps"] == weights["training"]["steps"] == 2
    assert summary["rank_parameters_sha256"] == weights["training"]["rank_parameters_sha256"]
    assert json.loads((out / ".lfbench-outputs.train.json").read_text()) == {"entries": ["final.pt", "summary.json"]}
    (out / "summary.json").unlink()  # as a kill between the two writes of an earlier version left it
    rc, _, err = run_cli(capsys, "-q", "train", config, "--out", out, "--no-progress")
    assert rc == 0, err
    assert json.loads((out / "summary.json").read_text())["steps"] == 2
