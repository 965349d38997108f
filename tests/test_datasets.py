"""The dataset seam (issue 30): adapters in the entry-point group ``lfbench.datasets``, layout detection,
UrbanLF-Syn read and scored by its protocol on non-square views, the plane sweep's range from the dataset,
and bad input in the UrbanLF-Syn layout (one line naming the file, exit 2, nothing written)."""

from __future__ import annotations

import dataclasses
import json
import shutil
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, run_cli
from PIL import Image

from lfbench.data.dataset import DATASETS, detect_dataset, method_range_params, open_dataset
from lfbench.data.hci import HCIDataset
from lfbench.data.synth import generate_scene, quantize, write_benchmark
from lfbench.data.synth_urbanlf import write_urbanlf
from lfbench.data.urbanlf import URBANLF_DISPARITY_RANGE, UrbanLFScene, UrbanLFSyn
from lfbench.method.registry import create_from_spec
from lfbench.utils.errors import DataError

W, H = 48, 32  # non-square, small: 81 views render in well under a second


@pytest.fixture(scope="module")
def urban_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("urban")
    write_urbanlf(root, seed=3, width=W, height=H, scenes=2, split="val")
    return root


@pytest.fixture()
def urban_copy(urban_root: Path, tmp_path: Path) -> Path:
    """A writable copy of one sample as ROOT/val/Image1 (to be broken by a test)."""
    dst = tmp_path / "root" / "val" / "Image1"
    shutil.copytree(urban_root / "val" / "Image1", dst)
    return dst


def test_builtin_datasets_come_through_the_entry_point_group():
    eps = {ep.name: ep.value for ep in metadata.entry_points(group="lfbench.datasets")}
    assert eps == {"hci": "lfbench.data.hci:HCIDataset", "urbanlf-syn": "lfbench.data.urbanlf:UrbanLFSyn",
                   "toml": "lfbench.data.generic:GenericDataset"}
    assert DATASETS.names() == ["hci", "toml", "urbanlf-syn"]
    assert DATASETS.get("hci") is HCIDataset and DATASETS.get("urbanlf-syn") is UrbanLFSyn


def test_datasets_command_lists_the_protocols(capsys):
    rc, out, err = run_cli(capsys, "datasets")
    assert rc == 0, err
    assert "urbanlf-syn: UrbanLF-Syn" in out and "hci: HCI 4D" in out
    assert "views: 9x9, 640x480 px (W x H); scored: centre view 5_5.png, 15 px border" in out
    assert "disparity range: [-0.5, 1.6] px per view step" in out
    assert "disparity range: [-4, 4] px per view step" in out
    assert "metrics: badpix_0.01, badpix_0.03, badpix_0.07, mse_x100\n" in out
    assert "high-resolution scenes: backgammon, dots, stripes" in out


def test_protocols_feed_the_scoring_rules():
    from lfbench.scoring.rules import ScoringRules

    hci = ScoringRules.of_protocol(HCIDataset.protocol)
    assert (hci.border_px, hci.highres_scenes, hci.allow_highres) == (15, {"backgammon", "dots", "stripes"}, True)
    assert hci == ScoringRules()  # HCI's protocol is the benchmark's default rules, field for field
    urban = ScoringRules.of_protocol(UrbanLFSyn.protocol, toolkit=True)
    assert (urban.border_px, urban.highres_scenes, urban.allow_highres, urban.toolkit) == (15, frozenset(), False, True)


def test_synth_urbanlf_layout_is_exact_and_non_square(urban_root: Path):
    sample = urban_root / "val" / "Image1"
    views = sorted(p.name for p in sample.glob("*_*.png"))
    assert len(views) == 81 and "1_1.png" in views and "9_9.png" in views
    assert Image.open(sample / "5_5.png").size == (W, H)
    gt = np.load(sample / "5_5_disparity.npy")
    assert gt.shape == (H, W) and gt.dtype == np.float32
    # the written files are the generator's square scene cropped to the centre H x W in every view
    from lfbench.data.synth import scene_seed
    square = generate_scene(scene_seed(3, 0), size=W, angular=9, disparity_range=URBANLF_DISPARITY_RANGE)
    y0 = (W - H) // 2
    np.testing.assert_array_equal(gt, square.disparity[y0:y0 + H])
    lo, hi = URBANLF_DISPARITY_RANGE  # UrbanLF-Syn's released range, not the generator's own [-2.1, 2.3]
    assert lo <= gt.min() < gt.max() <= hi
    np.testing.assert_array_equal(np.asarray(Image.open(sample / "2_7.png")), quantize(square.views[1, 6, y0:y0 + H]))


def test_urbanlf_scene_reads_rows_and_columns(urban_root: Path):
    scene = UrbanLFScene(urban_root / "val" / "Image1", category="val")
    assert scene.angular_size == (9, 9) and scene.spatial_size == (H, W)
    views = scene.gray_views()
    assert views.shape == (9, 9, H, W)
    row3_col8 = np.asarray(Image.open(urban_root / "val" / "Image1" / "3_8.png").convert("RGB"), np.float32) / 255
    np.testing.assert_allclose(scene.rgb_views()[2, 7], row3_col8)
    assert scene.center_view().shape == (H, W, 3)
    assert scene.has_gt() and scene.gt_disparity().shape == (H, W) and scene.mask_names() == []


@pytest.mark.parametrize("level", ["root", "split", "sample"])
def test_detection_at_each_level(urban_root: Path, level: str):
    root = {"root": urban_root, "split": urban_root / "val", "sample": urban_root / "val" / "Image2"}[level]
    assert detect_dataset(root) is UrbanLFSyn
    dataset, bench = open_dataset(root)
    assert dataset is UrbanLFSyn
    assert bench.names == (["Image1", "Image2"] if level != "sample" else ["Image2"])
    assert {s.category for s in bench} == {"val"}
    assert [s.name for s in bench.select(["val"])] == bench.names  # a split is a category here


def test_hci_layout_detected(tmp_path: Path):
    write_benchmark(tmp_path, seed=0, size=16, scenes=1, angular=3)
    assert detect_dataset(tmp_path) is HCIDataset


def test_root_of_no_layout_or_several_is_one_line(tmp_path: Path, urban_root: Path, capsys):
    (tmp_path / "empty").mkdir()
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "empty", "--method", "gt", "--out", tmp_path / "o")
    assert_one_error_line(rc, err, "no known dataset layout", "empty")
    both = tmp_path / "both"
    shutil.copytree(urban_root / "val", both / "val")
    write_benchmark(both, seed=0, size=16, scenes=1, angular=3)
    rc, _, err = run_cli(capsys, "evaluate", "--data", both, "--method", "gt", "--out", tmp_path / "o")
    assert_one_error_line(rc, err, "matches several datasets (hci, urbanlf-syn)", "--dataset")
    rc, _, err = run_cli(capsys, "evaluate", "--data", urban_root, "--dataset", "hci", "--method", "gt",
                         "--out", tmp_path / "o")
    assert_one_error_line(rc, err, "not laid out as dataset 'hci'")
    rc, _, err = run_cli(capsys, "evaluate", "--data", urban_root, "--dataset", "nope", "--method", "gt",
                         "--out", tmp_path / "o")
    assert_one_error_line(rc, err, "Unknown dataset 'nope'", "hci, toml, urbanlf-syn")
    assert not (tmp_path / "o").exists()
    # --dataset resolves the ambiguity
    rc, _, err = run_cli(capsys, "evaluate", "--data", both, "--dataset", "urbanlf-syn", "--method", "gt",
                         "--out", tmp_path / "o", "--no-progress")
    assert rc == 0, err


def test_evaluate_scores_urbanlf_by_its_protocol(urban_root: Path, tmp_path: Path, capsys):
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", urban_root, "--method", "gt", "--method", "constant:value=0.5",
                         "--out", out, "--no-progress", "--save-maps", "--figures", "--html")
    assert rc == 0, err
    data = json.loads((out / "results.json").read_text())
    assert data["meta"]["dataset"] == "urbanlf-syn"
    assert data["meta"]["scoring"]["border_px"] == 15 and data["meta"]["scoring"]["highres_scenes"] == []
    recs = {(r["method"], r["scene"], r["metric"]): r for r in data["records"]}
    assert {r["metric"] for r in data["records"]} == {"badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100"}
    assert {r["resolution"] for r in data["records"]} == {"lowres"}
    for scene in ("Image1", "Image2"):
        assert recs[("gt", scene, "mse_x100")]["value"] == 0.0
        assert recs[("gt", scene, "badpix_0.07")]["value"] == 0.0
        gt = np.load(urban_root / "val" / scene / "5_5_disparity.npy")[15:-15, 15:-15]  # 2 x 18 px scored
        err_ = np.abs(gt.astype(np.float64) - 0.5)
        assert recs[("constant:value=0.5", scene, "mse_x100")]["value"] == pytest.approx(100 * np.mean(err_**2),
                                                                                          rel=1e-5)
        assert recs[("constant:value=0.5", scene, "badpix_0.07")]["value"] == pytest.approx(
            100 * np.mean(err_ > 0.07), abs=1e-9)
    saved = out / "maps" / "constant_value_0.5" / "disp_maps"
    maps = sorted(saved.glob("*.pfm")) if saved.is_dir() else sorted((out / "maps").rglob("*.pfm"))
    from lfbench.data.pfm import read_pfm
    assert maps and all(read_pfm(p).shape == (H, W) for p in maps)
    assert (out / "html" / "index.html").is_file()
    pngs = list((out / "figures").rglob("*.png"))
    assert pngs


def _grid(protocol):
    return method_range_params(protocol.disparity_range, protocol.disparity_interval)


def test_planesweep_range_follows_the_dataset():
    urban, hci = _grid(UrbanLFSyn.protocol), _grid(HCIDataset.protocol)
    m = create_from_spec("planesweep", {"device": "cpu"}, urban)  # UrbanLF-Syn's grid: the paper's 0.1 px
    assert m.label == "planesweep:d_min=-0.5,d_max=1.6,interval=0.1"
    assert len(m.disparities) == 22 and float(m.disparities[0]) == pytest.approx(-0.5)
    assert float(m.disparities[-1]) == pytest.approx(1.6)
    coarse = create_from_spec("planesweep:interval=0.25", {"device": "cpu"}, urban)  # the spec's interval wins
    assert coarse.label == "planesweep:d_min=-0.5,d_max=1.75,interval=0.25"  # the 0.25 px grid covering 1.6
    assert float(coarse.disparities[-1]) == pytest.approx(1.75)
    assert create_from_spec("planesweep", {"device": "cpu"}, hci).label == "planesweep"  # HCI labels unchanged
    assert create_from_spec("planesweep:d_max=3", None, urban).label == "planesweep:d_max=3.0"  # the spec wins
    assert create_from_spec("constant", None, urban).label == "constant"  # no range parameters: untouched


def test_the_protocols_declare_the_interval_searched():
    """Issue 30.3: UrbanLF-Syn [-0.5, 1.6] at 0.1 px (the paper's Table III grid); HCI leaves the interval to
    each method (its numbers are the methods' defaults: plane sweep 0.25, SubFocal 0.5), so nothing changes."""
    assert (UrbanLFSyn.protocol.disparity_range, UrbanLFSyn.protocol.disparity_interval) == ((-0.5, 1.6), 0.1)
    assert (HCIDataset.protocol.disparity_range, HCIDataset.protocol.disparity_interval) == ((-4.0, 4.0), None)
    free = create_from_spec("subfocal:width=8", {"device": "cpu"}, _grid(UrbanLFSyn.protocol))  # no weights
    assert (free.params["d_min"], free.params["d_max"], free.params["interval"]) == (-0.5, 1.6, 0.1)
    for spec in ("planesweep", "subfocal:width=8", "lfattnet"):  # HCI: every method's own grid, label as before
        assert create_from_spec(spec, {"device": "cpu"}, _grid(HCIDataset.protocol)).label == spec
    hook = method_range_params((-4.0, 4.0), 0.1)  # a range that is the default, an interval that is not
    plain = create_from_spec("planesweep", {"device": "cpu"}, hook)
    assert plain.label == "planesweep:interval=0.1" and len(plain.disparities) == 81
    with pytest.raises(ValueError, match="disparity interval"):
        dataclasses.replace(UrbanLFSyn.protocol, disparity_interval=3.0)  # more than max - min
    with pytest.raises(ValueError, match="disparity interval"):
        dataclasses.replace(UrbanLFSyn.protocol, disparity_interval=float("nan"))


def test_evaluate_searches_the_dataset_grid(urban_root: Path, tmp_path: Path, capsys):
    rc, _, err = run_cli(capsys, "evaluate", "--data", urban_root, "--method", "planesweep", "--out", tmp_path / "o",
                         "--no-progress", "--scenes", "Image1")
    assert rc == 0, err
    data = json.loads((tmp_path / "o" / "results.json").read_text())
    assert {r["method"] for r in data["records"]} == {"planesweep:d_min=-0.5,d_max=1.6,interval=0.1"}
    rc, out, _ = run_cli(capsys, "datasets")
    assert "disparity range: [-0.5, 1.6] px per view step, interval 0.1 px" in out
    assert "disparity range: [-4, 4] px per view step, each method's own interval" in out


# ------------------------------------------------------------------------------------------- bad input


def _evaluate_fails(capsys, root: Path, tmp_path: Path, *fragments: str) -> None:
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", root, "--method", "gt", "--out", out, "--no-progress")
    assert_one_error_line(rc, err, *fragments)
    assert not out.exists()


def test_missing_view(urban_copy: Path, tmp_path: Path, capsys):
    (urban_copy / "3_4.png").unlink()
    (urban_copy / "9_9.png").unlink()
    _evaluate_fails(capsys, urban_copy.parents[1], tmp_path, "missing 2 of 81 views: 3_4.png, 9_9.png", "Image1")


def test_extra_view(urban_copy: Path, tmp_path: Path, capsys):
    shutil.copy(urban_copy / "1_1.png", urban_copy / "10_1.png")
    _evaluate_fails(capsys, urban_copy.parents[1], tmp_path, "unexpected view 10_1.png", "Image1/10_1.png")


def test_views_of_mixed_sizes(urban_copy: Path, tmp_path: Path, capsys):
    Image.new("RGB", (W, H + 2)).save(urban_copy / "7_2.png")
    _evaluate_fails(capsys, urban_copy.parents[1], tmp_path, f"view is {W}x{H + 2}", f"5_5.png is {W}x{H}",
                    "7_2.png")


def test_ground_truth_of_the_wrong_shape(urban_copy: Path, tmp_path: Path, capsys):
    np.save(urban_copy / "5_5_disparity.npy", np.zeros((W, H), np.float32))
    _evaluate_fails(capsys, urban_copy.parents[1], tmp_path, f"shape ({W}, {H}), expected ({H}, {W})",
                    "5_5_disparity.npy")


def test_ground_truth_not_finite(urban_copy: Path, tmp_path: Path, capsys):
    gt = np.load(urban_copy / "5_5_disparity.npy")
    gt[4, 5] = np.nan
    gt[6, 7] = np.inf
    np.save(urban_copy / "5_5_disparity.npy", gt)
    _evaluate_fails(capsys, urban_copy.parents[1], tmp_path, "2 non-finite values", "5_5_disparity.npy")


def test_ground_truth_not_a_npy(urban_copy: Path):
    (urban_copy / "5_5_disparity.npy").write_bytes(b"not an array")
    with pytest.raises(DataError, match="bad magic or header"):
        UrbanLFScene(urban_copy)


def test_test_split_without_ground_truth_is_not_scored(urban_copy: Path, tmp_path: Path, capsys):
    (urban_copy / "5_5_disparity.npy").unlink()
    scene = UrbanLFScene(urban_copy)
    assert not scene.has_gt() and scene.gt_disparity() is None
    _evaluate_fails(capsys, urban_copy.parents[1], tmp_path, "none of the selected scenes has ground truth")


def test_predict_reads_an_urbanlf_sample_folder(urban_root: Path, tmp_path: Path, capsys):
    out = tmp_path / "gt.npy"
    rc, _, err = run_cli(capsys, "predict", "--method", "gt", "--input", urban_root / "val" / "Image1", "--out", out)
    assert rc == 0, err
    np.testing.assert_array_equal(np.load(out), np.load(urban_root / "val" / "Image1" / "5_5_disparity.npy"))


def test_synth_command_writes_the_urbanlf_layout(tmp_path: Path, capsys):
    rc, out, err = run_cli(capsys, "synth", "--layout", "urbanlf-syn", "--size", "40x24", "--scenes", "1",
                           "--out", tmp_path / "u", "--seed", "3")
    assert rc == 0, err
    assert "wrote 1 UrbanLF-Syn sample(s) of 40x24 px, 9x9 views" in out
    sample = tmp_path / "u" / "val" / "Image1"
    assert Image.open(sample / "9_1.png").size == (40, 24) and np.load(sample / "5_5_disparity.npy").shape == (24, 40)
    assert detect_dataset(tmp_path / "u") is UrbanLFSyn
    rc, _, err = run_cli(capsys, "synth", "--size", "40x24", "--out", tmp_path / "h")
    assert_one_error_line(rc, err, "--size 40x24: the HCI layout has square views")
    assert not (tmp_path / "h").exists()


def test_synth_disparity_range_option(tmp_path: Path, capsys):
    rc, _, err = run_cli(capsys, "synth", "--layout", "urbanlf-syn", "--size", "40x24", "--scenes", "1",
                         "--out", tmp_path / "u", "--seed", "3", "--disparity-range", "-1", "0.5")
    assert rc == 0, err
    gt = np.load(tmp_path / "u" / "val" / "Image1" / "5_5_disparity.npy")
    assert -1 <= gt.min() < gt.max() <= 0.5
    rc, _, err = run_cli(capsys, "synth", "--size", "24", "--scenes", "1", "--out", tmp_path / "h", "--seed", "3",
                         "--disparity-range", "0", "2", "--workers", "1", "--no-progress")
    assert rc == 0, err
    hci = HCIDataset.open(tmp_path / "h").scenes[0].gt_disparity()
    assert 0 <= hci.min() < hci.max() <= 2
    for layout in ("hci", "urbanlf-syn"):
        out = tmp_path / f"bad_{layout}"
        rc, _, err = run_cli(capsys, "synth", "--layout", layout, "--size", "24", "--out", out,
                             "--disparity-range", "-5", "1")
        assert_one_error_line(rc, err, "disparity range [-5, 1] px", "at most 4.41 px")
        assert not out.exists()


def test_jobs_score_urbanlf_scenes_in_workers_with_the_same_numbers(urban_root: Path, tmp_path: Path, capsys):
    import pickle

    scene = UrbanLFScene(urban_root / "val" / "Image1", category="val")
    scene.gray_views()  # loaded views do not travel: the scene pickles as its folder and layout
    again = pickle.loads(pickle.dumps(scene))
    assert len(pickle.dumps(scene)) < 2000 and "_views" not in again.__dict__
    assert (again.path, again.category, again.spatial_size, type(again)) == (scene.path, "val", (H, W), UrbanLFScene)
    runs = {}
    for jobs in ("1", "2"):
        out = tmp_path / f"j{jobs}"
        rc, _, err = run_cli(capsys, "evaluate", "--data", urban_root, "--method", "constant:value=0.25",
                             "--method", "gt", "--jobs", jobs, "--out", out, "--no-progress")
        assert rc == 0, err
        runs[jobs] = json.loads((out / "results.json").read_text())["records"]
    assert runs["1"] == runs["2"] and len(runs["1"]) == 2 * 2 * 4


# ------------------------------------------------------------------------------------------- the seam itself


_HCI_FILE_NAMES = ("input_Cam", "parameters.cfg", "gt_disp_", "gt_depth_")


def _file_name_literals(path: Path, suffixes: tuple[str, ...] = ()) -> list[tuple[int, str]]:
    """(line, text) of every string in ``path``'s code that starts with an HCI file name (a file named in
    code: ``folder / "parameters.cfg"``, ``f"input_Cam{k:03d}.png"``) or, with ``suffixes``, ends with one of
    them; docstrings, comments and prose (help texts that mention a file mid-sentence) are not file names and
    are left out."""
    import ast

    tree = ast.parse(path.read_text(encoding="utf-8"))
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
                  and node.body and isinstance(node.body[0], ast.Expr)
                  and isinstance(node.body[0].value, ast.Constant)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):  # an f-string: its first and last literal parts hold the name's ends
            ends = [part.value if isinstance(part, ast.Constant) and isinstance(part.value, str) else ""
                    for part in (node.values[:1] + node.values[-1:])] if node.values else ["", ""]
            if ends[0].startswith(_HCI_FILE_NAMES) or (suffixes and ends[-1].endswith(suffixes)):
                found.append((node.lineno, "".join(ends)))
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings
              and (node.value.startswith(_HCI_FILE_NAMES) or (suffixes and node.value.endswith(suffixes)))):
            found.append((node.lineno, node.value))
    return found


def test_hci_file_names_live_in_the_hci_adapter_only():
    """Issue 30.1: the generic data code (the scene contract, the dataset seam, the pattern layouts) names no
    HCI file; HCI's view names, parameters.cfg and PFM ground truth are lfbench/data/hci/'s, for reading and
    for writing (the synthetic generator and the metrics bench write their scenes through the adapter's
    writer, lfbench.data.dataset.Dataset.write_scene; the scoring benchmarks through lfbench.data.hci.scene's
    names): no module of lfbench or benchmarks/ outside lfbench/data/hci/ names one of its files in code."""
    import lfbench
    import lfbench.data as data

    folder = Path(data.__file__).parent
    generic = ["scene.py", "dataset.py", "pattern.py", "generic.py", "urbanlf.py", "camera.py", "synth.py"]
    for name in generic:
        text = (folder / name).read_text(encoding="utf-8")
        for hci_only in ("input_Cam", "parameters.cfg", "gt_disp_", "SceneParameters"):
            assert hci_only not in text, (name, hci_only)
    hci = "".join(p.read_text(encoding="utf-8") for p in (folder / "hci").glob("*.py"))
    assert all(word in hci for word in ("input_Cam", "parameters.cfg", "gt_disp_", "SceneParameters"))
    package = Path(lfbench.__file__).parent
    code = [*package.rglob("*.py"), *(Path(__file__).parents[1] / "benchmarks").glob("*.py")]
    named = {str(p): lines for p in sorted(code) if (folder / "hci") not in p.parents
             and (lines := _file_name_literals(p))}
    assert named == {}
    assert _file_name_literals(folder / "hci" / "scene.py")  # the check sees the names where they are
    # likewise the UrbanLF-Syn writer takes its file names (views, disparity, depth) from the urbanlf adapter
    assert _file_name_literals(folder / "synth_urbanlf.py", (".png", ".npy")) == []
    assert _file_name_literals(folder / "urbanlf.py", (".png", ".npy"))


def test_no_module_outside_the_hci_adapter_imports_it():
    """Issue 38: an adapter is the only place that knows a layout. No module of lfbench outside lfbench/data/hci/
    imports it: the default scoring rules read HCI's high-resolution scenes from its protocol, the generator and
    the metrics bench write and open their scenes through the dataset registry (DATASETS)."""
    import lfbench

    package = Path(lfbench.__file__).parent
    found = [f"{path.relative_to(package)}:{n}" for path in sorted(package.rglob("*.py"))
             if package / "data" / "hci" not in path.parents
             for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if "import" in line and "data.hci" in line]
    assert found == []


def test_a_scene_written_by_the_hci_writer_reads_back_exactly(tmp_path: Path):
    """lfbench.data.hci.write and the HCI reader agree on every file: a generated scene written by the writer
    opens through the HCI adapter with the generated views (as quantized), ground truth, masks and parameters."""
    from lfbench.data.hci.params import SceneParameters
    from lfbench.data.hci.write import write_hci_scene

    sc = generate_scene(5, size=24, angular=3, name="round", category="training")
    views = quantize(sc.views)
    write_hci_scene(tmp_path / "training" / "round", sc.params, views=views, disparity=sc.disparity,
                    depth=sc.depth, masks=sc.masks)
    assert HCIDataset.matches(tmp_path)
    (scene,) = HCIDataset.open(tmp_path).scenes
    assert (scene.name, scene.category, scene.angular_size, scene.spatial_size) == ("round", "training", (3, 3),
                                                                                    (24, 24))
    np.testing.assert_array_equal(scene.rgb_views(), views.astype(np.float32) / np.float32(255.0))
    gt = scene.gt_disparity()
    assert gt.dtype == np.float32 and np.array_equal(gt, sc.disparity)
    assert scene.params == SceneParameters.of(sc.params)
    assert sorted(scene.mask_names()) == sorted(sc.masks)
    for name, mask in sc.masks.items():
        np.testing.assert_array_equal(scene.mask(name), mask)
    assert not scene.has_gt("highres")


def test_an_hci_scene_pickles_as_its_folder(tmp_path: Path):
    """A scoring worker (--jobs N) gets any dataset's scene as its folder, reopened there, never its views."""
    import pickle

    from lfbench.data.hci import HCIScene
    from lfbench.data.scene import Scene

    root = tmp_path / "hci"
    write_benchmark(root, seed=1, size=24, scenes=1, category="training")
    scene = HCIDataset.open(root).scenes[0]
    assert isinstance(scene, HCIScene) and isinstance(scene, Scene)
    scene.gray_views()
    blob = pickle.dumps(scene)
    again = pickle.loads(blob)
    assert len(blob) < 2000 and "_views" not in again.__dict__
    assert (type(again), again.path, again.category, again.params) == (HCIScene, scene.path, "training", scene.params)
    np.testing.assert_array_equal(again.gray_views(), scene.gray_views())
