"""The README's "Your own dataset" section is enough on its own: its lfbench-dataset.toml is written from the
README's code block, scenes are laid out as its layout block says (views named by its pattern, 16-bit PNG
ground truth with its scale and offset), and its own `lfbench evaluate` command scores them by its protocol.
Then the generic adapter's bad input: unknown keys and impossible values, one line naming the TOML."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, code_blocks, readme_section, run_cli
from PIL import Image

from lfbench.data.dataset import detect_dataset
from lfbench.data.generic import SPEC_FILE, GenericDataset, read_dataset_spec
from lfbench.data.pfm import write_pfm
from lfbench.data.synth import generate_scene, quantize
from lfbench.utils.errors import DataError


def _write_scene(folder: Path, seed: int, width: int, height: int, rows: int, cols: int, pattern: str,
                 first: int, gt_file: str, scale: float, offset: float) -> np.ndarray:
    """A synthetic scene (square generator, cropped to W x H in every view) written with the README's names;
    returns the disparity the 16-bit ground truth decodes to."""
    assert rows == cols
    size = max(width, height)
    scene = generate_scene(seed, size=size, angular=rows)
    y0, x0 = (size - height) // 2, (size - width) // 2
    views = quantize(scene.views[:, :, y0:y0 + height, x0:x0 + width])
    folder.mkdir(parents=True)
    for r in range(rows):
        for c in range(cols):
            name = pattern.format(v=r + first, u=c + first, k=r * cols + c + first)
            Image.fromarray(views[r, c]).save(folder / name)
    disp = scene.disparity[y0:y0 + height, x0:x0 + width].astype(np.float64)
    raw = np.round((disp - offset) / scale).astype(np.uint16)
    Image.fromarray(raw).save(folder / gt_file)
    return raw.astype(np.float64) * scale + offset


@pytest.fixture(scope="module")
def readme_root(tmp_path_factory) -> tuple[Path, list[list[str]], dict]:
    blocks = code_blocks(readme_section("Your own dataset"))
    toml_text = next(body for lang, body in blocks if lang == "toml")
    first, _, rest = toml_text.partition("\n")
    assert first == f"# file: {SPEC_FILE}"
    root = tmp_path_factory.mktemp("readme_dataset")
    (root / SPEC_FILE).write_text(rest, encoding="utf-8")
    layout, protocol = read_dataset_spec(root / SPEC_FILE)
    gts = {}
    for i, name in enumerate(("alley", "tower")):
        gts[name] = _write_scene(root / name, 11 + i, 64, 48, *layout.angular, layout.pattern, layout.first,
                                 layout.gt_file, layout.gt_scale, layout.gt_offset)
    bash = next(body for lang, body in blocks if lang == "bash")
    commands = [shlex.split(line) for line in bash.splitlines() if line.startswith("lfbench ")]
    return root, commands, {"gts": gts, "layout": layout, "protocol": protocol}


def test_readme_dataset_is_scored_by_its_own_protocol(readme_root, tmp_path: Path, capsys):
    root, commands, facts = readme_root
    assert facts["layout"].pattern == "view_{v}_{u}.png" and facts["layout"].angular == (5, 5)
    assert facts["protocol"].disparity_range == (-3.0, 3.0)
    assert detect_dataset(root) is GenericDataset
    (command,) = commands
    assert command[:2] == ["lfbench", "evaluate"]
    args = [str(root) if a == "ROOT" else str(tmp_path / "out") if a == "out/" else a for a in command[1:]]
    rc, _, err = run_cli(capsys, *args, "--method", "gt", "--no-progress")
    assert rc == 0, err
    data = json.loads((tmp_path / "out" / "results.json").read_text())
    assert data["meta"]["dataset"] == "toml" and data["meta"]["scoring"]["border_px"] == 15
    assert {r["metric"] for r in data["records"]} == {"badpix_0.03", "badpix_0.07", "mse_x100"}
    # the plane sweep searched the range the TOML declares, and says so in its label
    assert {r["method"] for r in data["records"]} == {"planesweep:d_min=-3.0,d_max=3.0,interval=0.1", "constant",
                                                      "gt"}
    recs = {(r["method"], r["scene"], r["metric"]): r["value"] for r in data["records"]}
    for scene, gt in facts["gts"].items():
        assert recs[("gt", scene, "mse_x100")] == 0.0
        core = gt[15:-15, 15:-15]  # 48 x 64 px views: 18 x 34 px scored
        assert core.shape == (18, 34)
        assert recs[("constant", scene, "mse_x100")] == pytest.approx(100 * np.mean(core**2), rel=1e-5)
        assert recs[("constant", scene, "badpix_0.07")] == pytest.approx(100 * np.mean(np.abs(core) > 0.07))


def test_readme_command_with_the_planesweep_searches_the_declared_range(readme_root):
    from lfbench.data.dataset import method_range_params
    from lfbench.method.registry import create_from_spec

    _, _, facts = readme_root
    protocol = facts["protocol"]
    assert (protocol.disparity_range, protocol.disparity_interval) == ((-3.0, 3.0), 0.1)
    m = create_from_spec("planesweep", {"device": "cpu"},
                         method_range_params(protocol.disparity_range, protocol.disparity_interval))
    assert m.label == "planesweep:d_min=-3.0,d_max=3.0,interval=0.1" and len(m.disparities) == 61


@pytest.mark.parametrize(("text", "fragment"), [
    ('[views]\npattern = "v{k}.png"\nangular = 3\ncolour = true\n', "[views] unknown key(s): colour"),
    ('[view]\npattern = "v{k}.png"\n', "unknown key(s): view"),
    ('[views]\npattern = "v{u}.png"\nangular = 3\n', "must name a view by {v} and {u}"),
    ('[views]\npattern = "../v{k}.png"\nangular = 3\n', "must be a file name inside the scene folder"),
    ('[views]\npattern = "v{k}.png"\nangular = 0\n', "views.angular: must be in [1, 33]"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\nfirst = 2\n', "views.first: must be in [0, 1]"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ndisparity_range = [2.0, -2.0]\n',
     "min < max"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\nborder = -1\n', "protocol.border: must be in [0, 1024]"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\nmetrics = ["runtime"]\n', "not a general metric"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[ground_truth]\nfile = "d.tif"\n',
     "ground_truth.format: must be one of pfm, npy, png16"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[ground_truth]\nfile = "d.png"\nformat = "png16"\nscale = 0\n',
     "ground_truth.scale: must be a non-zero number"),
    ('[views\n', "invalid TOML"),
    # the search interval (issue 30.3): > 0, finite, at most the range's max - min; its name is exact
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ndisparity_interval = 0\n',
     "protocol.disparity_interval: must be > 0"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ndisparity_interval = -0.1\n',
     "protocol.disparity_interval: must be > 0"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ndisparity_interval = nan\n',
     "protocol.disparity_interval: must be a finite number"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ndisparity_interval = inf\n',
     "protocol.disparity_interval: must be a finite number"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ndisparity_range = [0.0, 1.0]\ndisparity_interval = 1.5\n',
     "at most the range's max - min (1)"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ndisparity_interval = "0.1"\n',
     "protocol.disparity_interval: expected float, got str"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ninterval = 0.1\n', "[protocol] unknown key(s): interval"),
    ('[views]\npattern = "v{k}.png"\nangular = 3\n[protocol]\ndisparity_range = [nan, 1.0]\n',
     "protocol.disparity_range: expected finite numbers"),
    ('views = 3\n', "[views] must be a table"),
    ('[views]\nangular = 3\n', "views.pattern: is required"),
    ('[views]\npattern = "v{k}.png"\nangular = 1\n', "views.angular: needs at least 2 views"),
    ('[views]\npattern = "v{k}.png"\nangular = [3, 3, 3]\n', "views.angular: expected int or list of 2 int"),
])
def test_bad_dataset_toml_is_one_line_naming_it(tmp_path: Path, capsys, text: str, fragment: str):
    root = tmp_path / "root"
    (root / "scene").mkdir(parents=True)
    (root / SPEC_FILE).write_text(text, encoding="utf-8")
    if "metric" not in fragment:  # metric ids are checked where they are scored (lfbench.scoring), not by the reader
        with pytest.raises(DataError, match=re.escape(fragment)):
            read_dataset_spec(root / SPEC_FILE)
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--method", "gt", "--out", tmp_path / "out")
    assert_one_error_line(rc, err, fragment, SPEC_FILE)
    assert not (tmp_path / "out").exists()


def test_generic_layout_bad_views_and_ground_truth(tmp_path: Path, capsys):
    root = tmp_path / "root"
    (root).mkdir()
    (root / SPEC_FILE).write_text('[views]\npattern = "v{k}.png"\nangular = 3\nfirst = 1\n'
                                  '[ground_truth]\nfile = "gt.npy"\n[protocol]\nborder = 4\n', encoding="utf-8")
    scene = root / "s"
    scene.mkdir()
    for k in range(1, 10):
        Image.new("RGB", (20, 16)).save(scene / f"v{k}.png")
    np.save(scene / "gt.npy", np.zeros((16, 20), np.float32))
    assert GenericDataset.open(root).names == ["s"]
    Image.new("RGB", (20, 16)).save(scene / "v10.png")
    with pytest.raises(DataError, match="unexpected view v10.png"):
        GenericDataset.open(root)
    (scene / "v10.png").unlink()
    np.save(scene / "gt.npy", np.zeros((20, 16), np.float32))
    with pytest.raises(DataError, match=r"shape \(20, 16\), expected \(16, 20\)"):
        GenericDataset.open(root)
    np.save(scene / "gt.npy", np.full((16, 20), np.inf, np.float32))
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--method", "gt", "--out", tmp_path / "out")
    assert_one_error_line(rc, err, "320 non-finite values", "gt.npy")
    assert not (tmp_path / "out").exists()


def _generic_root(tmp_path: Path, gt_format: str = "npy") -> Path:
    """ROOT/lfbench-dataset.toml and one 3x3 scene ROOT/s/ of 20x16 px views v1.png .. v9.png and gt.<format>
    (a 4 px border: the default 15 px would leave no pixel of 20x16 views to score)."""
    root = tmp_path / "root"
    root.mkdir()
    (root / SPEC_FILE).write_text('[views]\npattern = "v{k}.png"\nangular = 3\nfirst = 1\n'
                                  f'[ground_truth]\nfile = "gt.{gt_format}"\n[protocol]\nborder = 4\n',
                                  encoding="utf-8")
    scene = root / "s"
    scene.mkdir()
    for k in range(1, 10):
        Image.new("RGB", (20, 16)).save(scene / f"v{k}.png")
    gt = np.zeros((16, 20), np.float32)
    if gt_format == "npy":
        np.save(scene / "gt.npy", gt)
    else:
        write_pfm(scene / "gt.pfm", gt)
    return root


def _break_missing(scene: Path) -> None:
    (scene / "v4.png").unlink()


def _break_extra(scene: Path) -> None:
    Image.new("RGB", (20, 16)).save(scene / "v10.png")


def _break_sizes(scene: Path) -> None:
    Image.new("RGB", (20, 18)).save(scene / "v7.png")


def _break_gt_shape(scene: Path) -> None:
    np.save(scene / "gt.npy", np.zeros((20, 16), np.float32))


def _break_gt_nan(scene: Path) -> None:
    gt = np.zeros((16, 20), np.float32)
    gt[3, 4] = np.nan
    np.save(scene / "gt.npy", gt)


def _break_pfm_shape(scene: Path) -> None:
    write_pfm(scene / "gt.pfm", np.zeros((8, 20), np.float32))


def _break_pfm_inf(scene: Path) -> None:
    gt = np.zeros((16, 20), np.float32)
    gt[0, 0] = np.inf
    write_pfm(scene / "gt.pfm", gt)


@pytest.mark.parametrize(("gt_format", "damage", "fragments"), [
    ("npy", _break_missing, ("missing 1 of 9 views: v4.png", "root/s")),
    ("npy", _break_extra, ("unexpected view v10.png", "s/v10.png")),
    ("npy", _break_sizes, ("view is 20x18, the centre view v5.png is 20x16", "s/v7.png")),
    ("npy", _break_gt_shape, ("shape (20, 16), expected (16, 20)", "s/gt.npy")),
    ("npy", _break_gt_nan, ("1 non-finite values", "s/gt.npy")),
    ("pfm", _break_pfm_shape, ("s/gt.pfm",)),
    ("pfm", _break_pfm_inf, ("1 non-finite values", "s/gt.pfm")),
], ids=["missing-view", "extra-view", "mixed-sizes", "gt-shape", "gt-nan", "pfm-shape", "pfm-inf"])
def test_generic_layout_bad_scene_is_one_line_exit_2_nothing_written(tmp_path: Path, capsys, gt_format, damage,
                                                                     fragments):
    """Issue 30.7 in the generic layout, through `lfbench evaluate`: one line naming the file, exit 2, no output."""
    root = _generic_root(tmp_path, gt_format)
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--method", "gt", "--out", tmp_path / "ok",
                         "--no-progress")
    assert rc == 0, err  # the intact scene scores
    damage(root / "s")
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--method", "gt", "--out", out, "--no-progress")
    assert_one_error_line(rc, err, *fragments)
    assert not out.exists()
