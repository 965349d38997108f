"""Training: config, the authors' patch sampling and augmentation (geometry kept), the loop,
resume after a kill, and 2-process data-parallel training on CPU (gloo)."""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from lfbench.data.hci import HCIDataset, HCIScene
from lfbench.data.hci.params import SceneParameters
from lfbench.data.pfm import write_pfm
from lfbench.data.shift import angular_offsets, shift_views
from lfbench.training import checkpoint as ckpt
from lfbench.training.augment import SampleAugment, apply_augment, flip_rows, rotate90
from lfbench.training.config import AugmentConfig, DataConfig, TrainConfig
from lfbench.training.data import PatchSampler, load_scene_data
from lfbench.utils.errors import DataError, SpecError

REPO = Path(__file__).resolve().parents[1]
NO_AUGMENT = AugmentConfig(enabled=False)


# --------------------------------------------------------------------------- tiny HCI-layout scenes

def shifted_views(texture: np.ndarray, d: int, size: tuple[int, int]) -> np.ndarray:
    """(9, 9, H, W, ...) views of a fronto-parallel plane of integer disparity d:
    view_{u,v}(y, x) = texture(y + (v - 4) d + m, x + (u - 4) d + m), so that
    centre(x, y) = view_{u,v}(x - (u - 4) d, y - (v - 4) d) exactly."""
    h, w = size
    m = 4 * abs(d)
    v, u = np.meshgrid(np.arange(9), np.arange(9), indexing="ij")
    ys = np.arange(h)[None, None, :, None] + (v[..., None, None] - 4) * d + m
    xs = np.arange(w)[None, None, None, :] + (u[..., None, None] - 4) * d + m
    return texture[ys, xs]


def write_scene(folder: Path, rgb_views: np.ndarray, gt: np.ndarray, valid: np.ndarray | None = None) -> Path:
    """Write (9, 9, H, W, 3) uint8 views and (H, W) gt in the HCI layout."""
    folder.mkdir(parents=True, exist_ok=True)
    h, w = gt.shape
    params = SceneParameters(focal_length_mm=100.0, image_resolution_x_px=w, image_resolution_y_px=h,
                             sensor_size_mm=35.0, num_cams_x=9, num_cams_y=9, baseline_mm=10.0,
                             focus_distance_m=5.0, disp_min=-4.0, disp_max=4.0, name=folder.name,
                             category=folder.parent.name)
    (folder / "parameters.cfg").write_text(params.to_cfg(), encoding="utf-8")
    for k in range(81):
        Image.fromarray(rgb_views[k // 9, k % 9]).save(folder / f"input_Cam{k:03d}.png")
    write_pfm(folder / "gt_disp_lowres.pfm", gt.astype(np.float32))
    if valid is not None:
        Image.fromarray(np.where(valid, 255, 0).astype(np.uint8)).save(folder / "valid_mask.png")
    return folder


def plane_scene(folder: Path, d: int, size: int = 40, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    m = 4 * abs(d)
    texture = rng.integers(0, 256, (size + 2 * m, size + 2 * m, 3), dtype=np.uint8)
    return write_scene(folder, shifted_views(texture, d, (size, size)), np.full((size, size), d, np.float32))


@pytest.fixture(scope="module")
def data_root(tmp_path_factory) -> Path:
    """additional/{plane_a (d = 2), plane_b (d = -1)}, stratified/val (d = 1), all 40 x 40."""
    return plane_training_root(tmp_path_factory.mktemp("hci"))


def plane_training_root(root: Path) -> Path:
    """additional/{plane_a (d = 2), plane_b (d = -1)}, stratified/val (d = 1), all 40 x 40, under ``root``."""
    plane_scene(root / "additional" / "plane_a", 2, seed=1)
    plane_scene(root / "additional" / "plane_b", -1, seed=2)
    plane_scene(root / "stratified" / "val", 1, seed=3)
    return root


def scene_data(root: Path, name: str, invalid_area: Path | None = None):
    return load_scene_data(next(s for s in HCIDataset.open(root) if s.name == name), invalid_area)


def centre_mismatch(views: np.ndarray, d: float) -> float:
    """max |view_{u,v}(x - (u-4) d, y - (v-4) d) - centre(x, y)| away from the borders; views (81, P, P)."""
    t = torch.from_numpy(np.ascontiguousarray(views, dtype=np.float32))[None, :, None]
    out = shift_views(t, angular_offsets(9), torch.tensor([float(d)]), "bilinear")[0, 0, :, 0]
    b = int(np.ceil(4 * abs(d))) + 1
    centre = torch.from_numpy(np.ascontiguousarray(views[40]))
    return float((out[:, b:-b, b:-b] - centre[None, b:-b, b:-b]).abs().max())


# --------------------------------------------------------------------------- augmentation geometry

@pytest.mark.parametrize("d", [1, -2])
def test_flip_and_rotation_keep_the_light_field_geometry(d):
    rng = np.random.default_rng(0)
    p = 24
    views = shifted_views(rng.random((p + 8 * abs(d), p + 8 * abs(d))).astype(np.float32), d, (p, p))[None]
    label = np.full((1, p, p), d, np.float32)
    assert centre_mismatch(views[0].reshape(81, p, p), d) < 1e-5
    for flip in (False, True):
        for k in range(4):
            v, lab = flip_rows(views, label) if flip else (views, label)
            v, lab = rotate90(v, lab, k)
            assert centre_mismatch(v[0].reshape(81, p, p), lab[0, 0, 0]) < 1e-5, (flip, k)
            # the batched path (with gamma 1) does the same
            out, out_lab = apply_augment(views.copy(), label, [SampleAugment(flip=flip, rotation=k)])
            np.testing.assert_array_equal(out, np.clip(v, 0, 1))
    # negative controls: turning only the image, or flipping only its rows, breaks the geometry
    assert centre_mismatch(np.rot90(views, 1, axes=(3, 4))[0].reshape(81, p, p), d) > 0.3
    assert centre_mismatch(views[:, :, :, ::-1][0].reshape(81, p, p), d) > 0.3


def test_rotation_moves_pixels_and_views_as_numpy_rot90():
    views = np.arange(2 * 3 * 3 * 4 * 4, dtype=np.float32).reshape(2, 3, 3, 4, 4)
    label = np.arange(2 * 16, dtype=np.float32).reshape(2, 4, 4)
    v, lab = rotate90(views, label, 1)
    # (v, u) -> (U-1-u, v) and (y, x) -> (W-1-x, y): new[v', u', y', x'] = old[u', V-1-v', x', W-1-y']
    assert v[0, 0, 1, 2, 3] == views[0, 1, 2, 3, 1]
    assert lab[1, 2, 3] == label[1, 3, 1]
    v, lab = flip_rows(views, label)
    assert v[1, 0, 2, 1, 3] == views[1, 2, 2, 2, 3] and lab[0, 0, 1] == label[0, 3, 1]


def test_gamma_and_noise():
    rng = np.random.default_rng(0)
    views = rng.random((2, 9, 9, 8, 8)).astype(np.float32)
    label = np.zeros((2, 8, 8), np.float32)
    noise = np.full((9, 9, 8, 8), 0.5, np.float32)
    out, _ = apply_augment(views, label, [SampleAugment(gamma=0.8), SampleAugment(gamma=1.2, noise=noise)])
    np.testing.assert_allclose(out[0], views[0] ** 0.8, rtol=1e-6)
    np.testing.assert_allclose(out[1], np.clip(views[1] ** 1.2 + 0.5, 0, 1), rtol=1e-6)
    assert out.max() <= 1.0


# --------------------------------------------------------------------------- patch sampling

def test_gather_takes_the_strided_patch_and_divides_the_label(data_root):
    sd = scene_data(data_root, "plane_a")
    cfg = DataConfig(roots=(str(data_root),), patch=16, strides=(2,), stride_weights=(1.0,), random_gray=False)
    sampler = PatchSampler([sd], cfg, NO_AUGMENT)
    w = np.array([[0.299, 0.587, 0.114]], np.float32)
    c = {"scene": np.array([0]), "stride": np.array([2]), "y": np.array([3]), "x": np.array([5]), "w": w}
    views, label = sampler._gather(c)
    gray = HCIScene(data_root / "additional" / "plane_a").gray_views()  # (9, 9, 40, 40)
    np.testing.assert_allclose(views[0], gray[:, :, 3:3 + 32:2, 5:5 + 32:2], atol=2e-6)
    np.testing.assert_array_equal(label, np.full((1, 16, 16), 1.0))  # d = 2 at stride 2


def test_sampling_is_deterministic_and_split_by_rank(data_root):
    scenes = [scene_data(data_root, n) for n in ("plane_a", "plane_b")]
    cfg = DataConfig(roots=(str(data_root),), patch=16, strides=(1, 2), stride_weights=(8.0, 6.0))
    sampler = PatchSampler(scenes, cfg, AugmentConfig())
    v4, l4 = sampler.sample(7, 0, 5, 0, 4)
    v4b, l4b = sampler.sample(7, 0, 5, 0, 4)
    np.testing.assert_array_equal(v4, v4b)
    np.testing.assert_array_equal(l4, l4b)
    assert v4.shape == (4, 81, 16, 16) and v4.dtype == np.float32 and l4.shape == (4, 16, 16)
    # rank 0 takes samples 0-1, rank 1 samples 2-3 of the same global batch
    v_r0, _ = sampler.sample(7, 0, 5, 0, 2)
    v_r1, _ = sampler.sample(7, 0, 5, 2, 2)
    np.testing.assert_array_equal(np.concatenate([v_r0, v_r1]), v4)
    assert not np.array_equal(v_r0, v_r1)
    assert not np.array_equal(sampler.sample(7, 0, 6, 0, 4)[0], v4)  # next step: other samples
    assert not np.array_equal(sampler.sample(7, 1, 5, 0, 4)[0], v4)  # other stage: other samples


def test_stride_and_scene_probabilities(data_root):
    scenes = [scene_data(data_root, n) for n in ("plane_a", "plane_b")]
    cfg = DataConfig(roots=(str(data_root),), patch=8, scene_weights={"plane_a": 3.0})  # strides 1, 2, 3 (8:6:3)
    sampler = PatchSampler(scenes, cfg, NO_AUGMENT)
    n = 17000
    c = sampler._draw(np.random.default_rng(0), n)
    for s, p in zip((1, 2, 3), (8 / 17, 6 / 17, 3 / 17), strict=True):
        assert abs(np.mean(c["stride"] == s) - p) < 4 * np.sqrt(p * (1 - p) / n)
    assert abs(np.mean(c["scene"] == 0) - 0.75) < 4 * np.sqrt(0.75 * 0.25 / n)
    w = c["w"]
    assert np.allclose(w.sum(axis=1), 1) and w.min() > 0.05 / 3.15
    # starts: every strided patch fits inside the 40 x 40 scene
    last = c["y"] + c["stride"] * 7
    assert c["y"].min() == 0 and last.max() == 39 and (last <= 39).all()


def test_texture_rejection(tmp_path):
    rng = np.random.default_rng(4)
    texture = rng.integers(0, 256, (48, 48, 3), dtype=np.uint8)
    texture[:, :26] = 128  # the left half is flat
    write_scene(tmp_path / "x" / "half", shifted_views(texture, 1, (40, 40)), np.ones((40, 40), np.float32))
    sd = scene_data(tmp_path, "half")
    p = 16

    def textures(threshold):
        cfg = DataConfig(roots=(str(tmp_path),), patch=p, strides=(1,), stride_weights=(1.0,), texture=threshold,
                         random_gray=False)
        views, _ = PatchSampler([sd], cfg, NO_AUGMENT).sample(0, 0, 0, 0, 64)
        centre = views[:, 40]
        return np.abs(centre - centre[:, p // 2, p // 2][:, None, None]).sum(axis=(1, 2))

    assert (textures(0.0) < 0.01 * p * p).sum() > 5  # without rejection flat patches do come up
    assert (textures(0.01) >= 0.01 * p * p - 1e-4).all()


def test_masks_keep_patches_out(tmp_path):
    rng = np.random.default_rng(5)
    texture = rng.integers(0, 256, (56, 40, 3), dtype=np.uint8)
    gt = np.ones((48, 32), np.float32)
    gt[:12], gt[36:] = 3.0, 5.0
    valid = np.ones((48, 32), bool)
    valid[:12] = False  # valid_mask.png excludes the top rows
    write_scene(tmp_path / "hci" / "additional" / "kitchen", shifted_views(texture, 1, (48, 32)), gt, valid)
    area = tmp_path / "additional_invalid_area" / "kitchen"
    area.mkdir(parents=True)
    rgba = np.zeros((48, 32, 4), np.uint8)
    rgba[36:, :, 3] = 255  # the authors' file excludes the bottom rows (alpha > 0)
    Image.fromarray(rgba, "RGBA").save(area / "input_Cam040_invalid_ver2.png")
    cfg = DataConfig(roots=("x",), patch=16, strides=(1,), stride_weights=(1.0,))
    root = tmp_path / "hci"
    _, plain = PatchSampler([scene_data(root, "kitchen")], cfg, NO_AUGMENT).sample(0, 0, 0, 0, 48)
    assert (plain != 1).any()  # without the masks patches reach the other rows
    sd = scene_data(root, "kitchen", tmp_path / "additional_invalid_area")
    assert sd.blocked is not None and sd.blocked[:12].all() and sd.blocked[36:].all() and not sd.blocked[12:36].any()
    _, label = PatchSampler([sd], cfg, AugmentConfig()).sample(0, 0, 0, 0, 48)
    np.testing.assert_array_equal(label, 1.0)


def test_sampled_patches_keep_the_geometry(tmp_path):
    """End to end through the sampler: strides 1 and 2, random gray, gamma, flips, rotations."""
    plane_scene(tmp_path / "x" / "plane", 2, size=64, seed=6)
    sd = scene_data(tmp_path, "plane")
    cfg = DataConfig(roots=(str(tmp_path),), patch=24, strides=(1, 2), stride_weights=(1.0, 1.0))
    views, label = PatchSampler([sd], cfg, replace(AugmentConfig(), noise=0.0)).sample(3, 0, 0, 0, 16)
    assert set(np.unique(label)) == {1.0, 2.0}
    for i in range(16):
        assert centre_mismatch(views[i], label[i, 0, 0]) < 1e-5
    assert not np.allclose(views[:, 40].mean(axis=(1, 2)), views[0, 40].mean())


# --------------------------------------------------------------------------- config

def test_example_configs_parse():
    for path in sorted((REPO / "configs").glob("*.toml")):
        cfg = TrainConfig.from_toml(path)
        assert cfg.stages and cfg.to_dict()["stages"][0]["loss"] in ("l1", "mae")
        assert TrainConfig.from_dict(cfg.to_dict()) == cfg


def test_config_errors(tmp_path):
    def parse(text):
        p = tmp_path / "c.toml"
        p.write_text(text)
        return TrainConfig.from_toml(p)

    base = '[data]\nroots = ["r"]\n'
    with pytest.raises(SpecError, match="stages"):
        parse(base)
    with pytest.raises(SpecError, match="Unknown loss"):
        parse(base + '[[stages]]\nloss = "huber"\nlr = 1e-3\nsteps = 1\n')
    with pytest.raises(SpecError, match="no parameter"):
        parse(base + '[[stages]]\nloss = "l1"\nbeta = 0.1\nlr = 1e-3\nsteps = 1\n')
    with pytest.raises(SpecError, match=r"unknown key\(s\): batch"):
        parse(base + '[training]\nbatch = 3\n[[stages]]\nloss = "l1"\nsteps = 1\n')
    with pytest.raises(SpecError, match="expected int"):
        parse(base + '[training]\nbatch_size = "3"\n[[stages]]\nloss = "l1"\nsteps = 1\n')
    with pytest.raises(SpecError, match="c.toml"):
        parse("[data\n")
    cfg = parse(base + '[[stages]]\nloss = "uafl"\nbeta = 0.1\nlr = 1e-4\nsteps = 5\n')
    assert cfg.stages[0].loss_params == {"beta": 0.1} and cfg.stages[0].eps == 1e-7


# --------------------------------------------------------------------------- training runs

def tiny_config(data_root: Path, **training) -> TrainConfig:
    t = {"batch_size": 1, "threads": 1, "checkpoint_every": 2, "log_every": 2, "prefetch": 1, **training}
    raw = {
        "seed": 5,
        "data": {"roots": [str(data_root)], "train": ["additional"], "validation": ["val"], "patch": 16,
                 "strides": [1, 2], "stride_weights": [8, 6], "scene_weights": {"plane_b": 2}},
        "model": {"width": 4},
        "training": t,
        "validation": {"every": 4, "max_size": 0},
        "stages": [{"name": "l1", "loss": "l1", "lr": 1e-3, "steps": 4},
                   {"name": "uafl", "loss": "uafl", "beta": 0.1, "lr": 1e-4, "steps": 2}],
    }
    return TrainConfig.from_dict(raw)


def write_toml(cfg: TrainConfig, path: Path) -> Path:
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float)):
            return repr(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return "{" + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + "}"

    d = cfg.to_dict()
    lines = [f"seed = {d['seed']}"]
    for table in ("data", "augment", "model", "training", "validation"):
        lines.append(f"[{table}]")
        lines += [f"{k} = {value(v)}" for k, v in d[table].items() if v is not None and v != []]
    for st in d["stages"]:
        lines.append("[[stages]]")
        lines += [f"{k} = {value(v)}" for k, v in st.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def load_state(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)


@pytest.fixture(scope="module")
def reference_run(data_root, tmp_path_factory):
    """An uninterrupted in-process run of the tiny two-stage config."""
    from lfbench.training.loop import train

    out = tmp_path_factory.mktemp("ref") / "out"
    cfg = tiny_config(data_root)
    result = train(cfg, out, progress=False, command="test")
    return cfg, out, result


def test_training_outputs(reference_run, data_root):
    from lfbench_methods.subfocal.network import SubFocalNet

    from lfbench.scoring.metrics import bad_pix, mse_x100
    from lfbench.scoring.prepare import border_mask

    cfg, out, result = reference_run
    assert result["steps"] == 6
    final = load_state(out / "final.pt")
    assert final["format"] == ckpt.WEIGHTS_FORMAT and final["config"]["width"] == 4
    net = SubFocalNet(**final["config"])
    net.load_state_dict(final["state_dict"])
    params = {n: final["state_dict"][n] for n, _ in net.named_parameters()}
    assert final["training"]["rank_parameters_sha256"] == [ckpt.state_sha256(params)]
    # stage 2 started from the stage-1 weights and changed them; a fresh Adam at the boundary
    stage1 = load_state(out / "stage1_l1.pt")["state_dict"]
    assert any(not torch.equal(stage1[k], final["state_dict"][k]) for k in stage1)
    state = load_state(out / "checkpoint.pt")
    assert (state["stage"], state["step"], state["optimizer"]) == (2, 0, None)
    # the log: train lines every 2 steps, validation at step 4 of stage 1 (= end of stage) and at the end
    entries = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    train_steps = [e["global_step"] for e in entries if e["event"] == "train"]
    assert train_steps == [2, 4, 6]
    vals = [e for e in entries if e["event"] == "validation"]
    assert [v["global_step"] for v in vals] == [4, 6]
    # the last validation numbers are BadPix(0.07) / MSE x100 of the final weights (15 px border)
    scene = HCIScene(data_root / "stratified" / "val")
    views = scene.gray_views().reshape(1, 81, 40, 40)
    with torch.no_grad():
        pred = net.eval()(torch.from_numpy(np.ascontiguousarray(views)))[0][0].numpy()
    gt = scene.gt_disparity()
    mask = border_mask(gt.shape, 15)
    assert vals[-1]["pixels"] == 100
    assert vals[-1]["badpix"] == pytest.approx(bad_pix(gt, pred, 0.07, mask), abs=1.01)  # within one pixel
    assert vals[-1]["mse_x100"] == pytest.approx(mse_x100(gt, pred, mask), rel=1e-5)
    assert (out / "best.pt").is_file() and (out / "command.txt").read_text().strip().endswith("test")


def _scalars(out: Path) -> dict[str, list[tuple[int, float]]]:
    """Every scalar of the TensorBoard event files in ``out``, read back with tensorboard itself."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(out))
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def test_training_writes_tensorboard_events_and_a_learning_curve(reference_run):
    pytest.importorskip("tensorboard", reason="tensorboard is not installed (pip install -e .[test])")
    _, out, _ = reference_run
    entries = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    train_entries = [e for e in entries if e["event"] == "train"]
    vals = [e for e in entries if e["event"] == "validation"]
    scalars = _scalars(out)
    # the same numbers as the JSON log, at the same global steps (float32 in the event files)
    for key, tag in (("loss", "train/loss"), ("lr", "train/learning_rate"), ("steps_per_s", "train/steps_per_s")):
        assert [s for s, _ in scalars[tag]] == [e["global_step"] for e in train_entries]
        np.testing.assert_allclose([v for _, v in scalars[tag]], [e[key] for e in train_entries], rtol=1e-6)
    for key in ("badpix", "mse_x100"):
        for tag, want in ((f"validation/{key}", [e[key] for e in vals]),
                          (f"validation/val/{key}", [e["scenes"]["val"][key] for e in vals])):
            assert [s for s, _ in scalars[tag]] == [e["global_step"] for e in vals]
            np.testing.assert_allclose([v for _, v in scalars[tag]], want, rtol=1e-6)
    assert (out / "learning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_validation_entries_name_their_badpix_threshold_for_the_curve(reference_run):
    from lfbench.training.curves import _validation_labels, read_metrics

    cfg, out, _ = reference_run
    vals = [e for e in read_metrics(out / "metrics.jsonl") if e["event"] == "validation"]
    assert [v["threshold"] for v in vals] == [cfg.validation.threshold] * 2 == [0.07, 0.07]
    assert _validation_labels(vals) == ("BadPix 0.07 (%)", "MSE x100")  # the learning curve's axis labels


def test_without_tensorboard_the_run_says_so_in_one_line(monkeypatch, caplog):
    from lfbench.training import curves

    monkeypatch.setattr(curves, "tensorboard_available", lambda: False)
    with caplog.at_level("INFO", logger="lfbench.training.curves"):
        loggers = curves.default_loggers(Path("unused"))
    assert [type(lg).__name__ for lg in loggers] == ["LearningCurveLogger"]
    (line,) = [r.getMessage() for r in caplog.records]
    assert "tensorboard is not installed" in line and "lfbench[tensorboard]" in line and "\n" not in line


def run_cli(args: list[str], **kw) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen([sys.executable, "-m", "lfbench", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, **kw)


@pytest.mark.slow
def test_resume_after_kill_matches_an_uninterrupted_run(reference_run, tmp_path):
    cfg, ref_out, _ = reference_run
    config = write_toml(cfg, tmp_path / "tiny.toml")
    out = tmp_path / "out"
    proc = run_cli(["train", str(config), "--out", str(out), "--no-progress"])
    deadline = time.monotonic() + 120
    while not (out / "checkpoint.pt").is_file():
        assert proc.poll() is None, proc.communicate()[0]
        assert time.monotonic() < deadline
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "final.pt").exists(), "the run finished before it was killed; make it longer"
    killed_at = load_state(out / "checkpoint.pt")["global_step"]
    assert 0 < killed_at < 6
    # the same command again resumes from the checkpoint and finishes
    rerun = run_cli(["train", str(config), "--out", str(out), "--no-progress"])
    log, _ = rerun.communicate(timeout=300)
    assert rerun.returncode == 0, log
    assert "resuming from" in log and f"(global step {killed_at})" in log
    final, ref = load_state(out / "final.pt"), load_state(ref_out / "final.pt")
    for k, v in ref["state_dict"].items():
        assert torch.equal(final["state_dict"][k], v), k  # bit for bit: same batches, same arithmetic
    steps = [json.loads(x)["global_step"] for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert steps == [2, 4, 4, 6, 6]  # train/validation entries, none repeated across the kill
    if importlib.util.find_spec("tensorboard") is not None:  # nor in the TensorBoard events (purged on resume)
        assert [s for s, _ in _scalars(out)["train/loss"]] == [2, 4, 6]
    assert (out / "command.txt").read_text().count("lfbench train") == 2
    # a different config in the same folder is refused
    changed = tmp_path / "changed.toml"
    changed.write_text(config.read_text().replace("seed = 5", "seed = 6"))
    from lfbench.cli import main

    assert main(["train", str(changed), "--out", str(out)]) == 2


@pytest.mark.slow
def test_two_process_ddp_matches_one_process(data_root, tmp_path):
    """torchrun, 2 CPU processes (gloo), batch 2 = 1 per rank, against 1 process with batch 2 in
    2 micro-batches of 1. BatchNorm normalises with the statistics of the batch each process
    sees, so the 1-process comparison must use the same split (accumulate = 2): then the
    gradients are the same average up to float rounding, and the weights agree to ~1e-6."""
    from lfbench.training.loop import train

    base = tiny_config(data_root, batch_size=2, checkpoint_every=100, log_every=1, prefetch=0)
    cfg = TrainConfig.from_dict({**base.to_dict(), "validation": {"every": 0},
                                 "stages": [{"name": "l1", "loss": "l1", "lr": 1e-3, "steps": 2}]})
    config = write_toml(cfg, tmp_path / "ddp.toml")
    out = tmp_path / "ddp"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
                           "-m", "lfbench", "train", str(config), "--out", str(out), "--no-progress"],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Grad strides do not match" not in proc.stderr  # distributed.match_grad_strides
    final = load_state(out / "final.pt")
    # both ranks ended with bit-identical parameters (and these are the exported ones)
    digests = final["training"]["rank_parameters_sha256"]
    params = {n: final["state_dict"][n] for n, _ in _net(final).named_parameters()}
    assert len(digests) == 2 and digests[0] == digests[1] == ckpt.state_sha256(params)
    assert final["training"]["world_size"] == 2
    assert final["training"]["command"].startswith("torchrun --nproc-per-node 2 -m lfbench train")

    single = TrainConfig.from_dict({**cfg.to_dict(), "training": {**cfg.to_dict()["training"], "accumulate": 2}})
    train(single, tmp_path / "single", progress=False)
    one = load_state(tmp_path / "single" / "final.pt")["state_dict"]
    torch.manual_seed(cfg.seed)
    init = _net(final).state_dict()  # the training starts from this (same seed)
    names = [n for n, _ in _net(final).named_parameters()]
    # training moved the weights (all but the 16-px SPP branch, whose 1x1 map BatchNorm zeroes at batch 1)
    assert sum(not torch.equal(init[n], one[n]) for n in names) >= len(names) - 3
    for n in names:
        torch.testing.assert_close(final["state_dict"][n], one[n], rtol=1e-4, atol=1e-6)
    # the logged losses (averaged over ranks) match the single process's
    def losses(folder: Path) -> list[float]:
        entries = [json.loads(x) for x in (folder / "metrics.jsonl").read_text().splitlines()]
        return [e["loss"] for e in entries if e["event"] == "train"]

    assert len(losses(out)) == 2
    np.testing.assert_allclose(losses(out), losses(tmp_path / "single"), rtol=1e-5)


def _net(final: dict):
    from lfbench_methods.subfocal.network import SubFocalNet

    return SubFocalNet(**final["config"])


def test_cli_errors(tmp_path, data_root):
    from lfbench.cli import main

    assert main(["train", str(tmp_path / "missing.toml")]) == 2
    cfg = tiny_config(data_root)
    config = write_toml(cfg, tmp_path / "c.toml")
    assert main(["train", str(config), "--out", str(tmp_path / "none"), "--resume"]) == 2
    bad = TrainConfig.from_dict({**cfg.to_dict(), "data": {**cfg.to_dict()["data"], "train": ["nosuch"]}})
    with pytest.raises(DataError, match="nosuch"):
        from lfbench.training.scenes import discover, select_scenes

        select_scenes(discover(bad, tmp_path), bad)


# --------------------------------------------------------------------------- many processes, many machines

def test_slurm_tasks_are_ranks_only_inside_an_srun_step():
    from lfbench.training.distributed import launch_env

    assert launch_env({}) == (1, 0, 0, "none")
    torchrun = {"WORLD_SIZE": "8", "RANK": "5", "LOCAL_RANK": "1", "SLURM_PROCID": "0", "SLURM_NTASKS": "2"}
    assert launch_env(torchrun) == (8, 5, 1, "torchrun")  # torchrun's variables win
    step = {"SLURM_STEP_ID": "0", "SLURM_STEP_NUM_TASKS": "8", "SLURM_NTASKS": "8", "SLURM_PROCID": "6",
            "SLURM_LOCALID": "2"}
    assert launch_env(step) == (8, 6, 2, "slurm")  # srun: 2 nodes x 4 GPUs, the 3rd task of the 2nd node
    assert launch_env({"SLURM_NTASKS": "8", "SLURM_PROCID": "0"}) == (1, 0, 0, "none")  # the batch script itself


def test_srun_without_a_master_address_is_one_line(monkeypatch):
    from lfbench.training import distributed

    for key in ("WORLD_SIZE", "RANK", "LOCAL_RANK", "MASTER_ADDR", "MASTER_PORT"):
        monkeypatch.delenv(key, raising=False)
    for key, value in {"SLURM_STEP_ID": "0", "SLURM_STEP_NUM_TASKS": "2", "SLURM_PROCID": "1",
                       "SLURM_LOCALID": "1"}.items():
        monkeypatch.setenv(key, value)
    with pytest.raises(SpecError, match="MASTER_ADDR / MASTER_PORT are not set"):
        distributed.setup("cpu")


def test_ranks_resuming_from_different_steps_stop_with_one_error():
    from lfbench.training.distributed import DistContext, agree_on_resume
    from lfbench.utils.errors import DataError, LFBenchError

    class TwoRanks(DistContext):
        def __init__(self, other):
            super().__init__(rank=0, world_size=2)
            self.other = other

        def gather(self, obj):
            return [obj, self.other]

    agree_on_resume(TwoRanks((0, 10, 10)), (0, 10, 10))  # the same position: go on
    agree_on_resume(TwoRanks(None), None)
    with pytest.raises(LFBenchError, match=r"rank 0: stage 2 step 10 \(global 10\), rank 1: fresh start"):
        agree_on_resume(TwoRanks(None), (1, 10, 10))
    with pytest.raises(LFBenchError, match="rank 1 could not resume: .*checkpoint.pt: unreadable"):
        agree_on_resume(TwoRanks("/x/checkpoint.pt: unreadable"), (1, 10, 10))
    with pytest.raises(DataError, match="unreadable"):  # one process: its own error, as before
        agree_on_resume(DistContext(), DataError("unreadable", "/x/checkpoint.pt"))


# --------------------------------------------------------------------------- throughput options

def test_dataloader_workers_give_the_same_batches_as_none(data_root, one_torch_thread):
    """Each sample's generator is derived from (seed, stage, step, index): 0 and 2 workers, and a start in the
    middle (a resume), give identical batches."""
    from lfbench.training.batches import batch_source

    cfg = tiny_config(data_root, batch_size=3)
    sampler = PatchSampler([scene_data(data_root, "plane_a"), scene_data(data_root, "plane_b")], cfg.data,
                           cfg.augment)

    def batches(workers: int, start: int) -> list:
        c = replace(cfg, training=replace(cfg.training, workers=workers))
        src = batch_source(sampler, c, 0, start, 6, 0, 3)
        try:
            return [tuple(np.asarray(x) for x in src.get(step)) for step in range(start, 6)]
        finally:
            src.close()

    plain, two = batches(0, 0), batches(2, 0)
    assert len(plain) == len(two) == 6
    for (v0, t0), (v2, t2) in zip(plain, two, strict=True):
        np.testing.assert_array_equal(v0, v2)
        np.testing.assert_array_equal(t0, t2)
    for (v0, _), (v4, _) in zip(plain[4:], batches(2, 4), strict=True):  # resumed at step 4
        np.testing.assert_array_equal(v0, v4)
    assert not np.array_equal(plain[0][0], plain[1][0])  # the steps differ


def test_throughput_options_parse_and_leave_old_fingerprints_alone(data_root):
    cfg = tiny_config(data_root)
    assert "workers" not in cfg.to_dict()["training"] and "precision" not in cfg.to_dict()["training"]
    fast = tiny_config(data_root, workers=2, precision="bf16", tf32=True, cudnn_benchmark=True, pin_memory=False)
    d = fast.to_dict()["training"]
    assert (d["workers"], d["precision"], d["tf32"], d["cudnn_benchmark"], d["pin_memory"]) == (2, "bf16", True,
                                                                                                   True, False)
    assert TrainConfig.from_dict(fast.to_dict()) == fast
    with pytest.raises(SpecError, match="precision"):
        tiny_config(data_root, precision="fp16")


def test_bf16_training_on_a_cpu_without_it_is_one_line(data_root, tmp_path, monkeypatch):
    from lfbench.training.loop import train

    monkeypatch.setenv("LFBENCH_FORCE_NO_BF16", "1")
    with pytest.raises(SpecError, match="training.precision = 'bf16' needs bf16 convolutions.*lacks avx512bw"):
        train(tiny_config(data_root, precision="bf16"), tmp_path / "bf16", progress=False)


@pytest.mark.slow
def test_bf16_autocast_and_workers_train(data_root, tmp_path, cpu_bf16):
    """bf16 autocast trains (finite loss, weights that differ from fp32 only by bf16 rounding), and 2 DataLoader
    workers give bit-identical weights to the prefetch thread."""
    from lfbench.training.loop import train

    base = {"validation": {"every": 0}, "stages": [{"name": "l1", "loss": "l1", "lr": 1e-3, "steps": 3}]}

    def run(name: str, **training) -> dict:
        cfg = tiny_config(data_root, **training)
        cfg = TrainConfig.from_dict({**cfg.to_dict(), **base})
        train(cfg, tmp_path / name, progress=False)
        return load_state(tmp_path / name / "final.pt")

    fp32, workers, bf16 = run("fp32"), run("workers", workers=2), run("bf16", precision="bf16")
    for k in fp32["state_dict"]:
        assert torch.equal(fp32["state_dict"][k], workers["state_dict"][k]), k
    # Both start from the same weights and Adam moves a parameter by about lr per step: 3 steps of lr 1e-3 each
    # keep every bf16 parameter within 2 x 3e-3 of the fp32 one; bf16 rounding makes them differ.
    names = [n for n, _ in _net(fp32).named_parameters()]
    diffs = [float((fp32["state_dict"][n] - bf16["state_dict"][n]).abs().max()) for n in names]
    assert all(np.isfinite(diffs)) and 0 < max(diffs) <= 6.5e-3
    assert all(torch.isfinite(v.float()).all() for v in bf16["state_dict"].values())


def test_training_devices_go_through_the_one_device_parser(data_root, monkeypatch):
    from lfbench.training.distributed import resolve_device

    with pytest.raises(SpecError, match=r"expected 'auto', 'cpu', 'cuda' or 'cuda:K', got 'cuda:x'"):
        tiny_config(data_root, device="cuda:x")
    assert resolve_device("auto", 3) == torch.device("cpu") or torch.cuda.is_available()
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    monkeypatch.setattr(torch.cuda, "current_device", lambda: 0)
    assert resolve_device("auto", 3) == torch.device("cuda", 1)  # local rank 3 of 2 GPUs per node
    assert resolve_device("cuda", 2) == torch.device("cuda", 0) and resolve_device("cuda:1", 0).index == 1
    with pytest.raises(SpecError, match="only 2 CUDA GPUs are visible"):
        resolve_device("cuda:5")


class _StopAt:
    """A run logger that interrupts training (as Ctrl-C does) once the log reaches ``global_step``."""

    def __init__(self, global_step: int) -> None:
        self.global_step = global_step

    def record(self, entry: dict) -> None:
        if entry["event"] == "train" and entry["global_step"] == self.global_step:
            os.kill(os.getpid(), signal.SIGINT)

    def close(self) -> None:
        pass


@pytest.mark.parametrize(("planned", "stop"), [(3, 2), (7, 2), (7, 4)], ids=["extended", "cut", "cut-at-step"])
def test_the_stage_in_progress_may_be_cut_or_extended_on_resume(reference_run, tmp_path, planned, stop):
    """Stage 1 planned with 3 or 7 steps, stopped at step 2 or 4, resumed with the reference config (4 steps):
    the same weights, bit for bit, and the same log as the run configured with 4 steps from the start (cut at
    step 4, the validation it ran before the stop is not repeated)."""
    from lfbench.training.loop import train
    from lfbench.training.signals import TrainingInterrupted

    cfg, ref_out, _ = reference_run
    raw = cfg.to_dict()
    raw["stages"] = [dict(raw["stages"][0], steps=planned), raw["stages"][1]]
    out = tmp_path / "out"
    with pytest.raises(TrainingInterrupted, match=f"stopped at stage 1 step {stop};"):
        train(TrainConfig.from_dict(raw), out, progress=False, loggers=[_StopAt(stop)])
    result = train(cfg, out, progress=False, loggers=[])
    assert result["resumed"] and result["steps"] == 6
    final, ref = load_state(out / "final.pt"), load_state(ref_out / "final.pt")
    for k, v in ref["state_dict"].items():
        assert torch.equal(final["state_dict"][k], v), k

    def log(folder: Path) -> list[tuple]:
        entries = [json.loads(x) for x in (folder / "metrics.jsonl").read_text().splitlines()]
        return [(e["event"], e["global_step"], e.get("loss", e.get("badpix"))) for e in entries]

    assert log(out) == log(ref_out)


def test_a_stage_cut_below_its_checkpoint_step_is_refused(reference_run, tmp_path):
    from lfbench.training.loop import train
    from lfbench.training.signals import TrainingInterrupted
    from lfbench.utils.errors import DataError, SpecError

    cfg, _, _ = reference_run
    out = tmp_path / "out"
    with pytest.raises(TrainingInterrupted):
        train(cfg, out, progress=False, loggers=[_StopAt(2)])
    raw = cfg.to_dict()
    raw["stages"] = [dict(raw["stages"][0], steps=1), raw["stages"][1]]
    with pytest.raises(DataError, match="stage 1 step 2, beyond the config's stages"):
        train(TrainConfig.from_dict(raw), out, progress=False, loggers=[])
    raw["stages"] = [dict(raw["stages"][0], lr=5e-4), raw["stages"][1]]  # any other change stays refused
    with pytest.raises(SpecError, match="only the steps of the stage in progress may change"):
        train(TrainConfig.from_dict(raw), out, progress=False, loggers=[])
