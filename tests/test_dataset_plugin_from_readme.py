"""The README's "A dataset adapter plugin" section is enough on its own (issue 38): its adapter module and the
entry point of its pyproject.toml, installed as pip would (no pip), read a dataset laid out as it says, which
`lfbench check-dataset` passes (the adapter's contract, then the grid's orientation) and `lfbench evaluate`
scores by its protocol. Then the contract check's refusals, each of an adapter broken in one way (the held-out
tests/npy7_plugin.py with one member overridden): one line naming the adapter, the scene and the problem,
exit 2; and the good npy7 plugin passes."""

from __future__ import annotations

import json
import tomllib
import uuid
from pathlib import Path

import numpy as np
import pytest
from helpers import (
    assert_one_error_line,
    code_blocks,
    forget_module,
    install_dataset_plugin,
    readme_section,
    run_cli,
    shifted_views,
)
from npy7_plugin import ANGULAR, write_npy7_scene

SECTION = "A dataset adapter plugin"
SIZE = 32  # px, square views
DISPARITIES = {"alley": 1, "tower": -1, "yard": 1}  # px per view step, integer: the views are exact shifts
ADAPTER = "'lf7' (my_lf7.adapter.Lf7Dataset)"


def _textured(seed: int, size: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) uint8 random texture holding both 0 and 255."""
    centre = np.random.default_rng(seed).integers(0, 256, size=(*size, 3), dtype=np.uint8)
    centre[0, 0], centre[0, 1] = 0, 255
    return centre


@pytest.fixture
def readme_plugin(tmp_path, monkeypatch) -> Path:
    """The README's adapter installed from its two code blocks, and a data root laid out as it says."""
    blocks = code_blocks(readme_section(SECTION))
    module = next(body for lang, body in blocks if lang == "python")
    first, _, source = module.partition("\n")
    assert first == "# file: my_lf7/adapter.py"
    project = next(body for lang, body in blocks if lang == "toml")
    assert project.startswith("# file: pyproject.toml\n")
    entry_points = tomllib.loads(project)["project"]["entry-points"]["lfbench.datasets"]
    assert entry_points == {"lf7": "my_lf7.adapter:Lf7Dataset"}
    site = tmp_path / "site"
    (site / "my_lf7").mkdir(parents=True)
    (site / "my_lf7" / "__init__.py").write_text("", encoding="utf-8")
    (site / "my_lf7" / "adapter.py").write_text(source, encoding="utf-8")
    install_dataset_plugin(site, monkeypatch, "my-lf7", entry_points)
    root = tmp_path / "lf7"
    for seed, (name, d) in enumerate(DISPARITIES.items()):
        folder = root / name
        folder.mkdir(parents=True)
        np.save(folder / "views.npy", shifted_views(_textured(seed, (SIZE, SIZE)), d, 7))
        np.save(folder / "disparity.npy", np.full((SIZE, SIZE), float(d), np.float32))
    yield root
    for name in ("my_lf7.adapter", "my_lf7"):
        forget_module(name)


def test_the_readme_adapter_passes_check_dataset_and_is_evaluated_by_its_protocol(readme_plugin, tmp_path, capsys):
    root = readme_plugin
    holds = f"adapter {ADAPTER}: contract holds on 3 scenes (views and ground truth read on 3)"
    rc, out, err = run_cli(capsys, "check-dataset", root, "--no-progress", "--adapter-only")
    assert (rc, out, err) == (0, holds + "\n", "")
    rc, out, err = run_cli(capsys, "check-dataset", root, "--no-progress")
    assert rc == 0 and err == "", err
    lines = out.splitlines()
    assert lines[0] == holds and len(lines) == 5, out
    for line, name in zip(lines[1:4], DISPARITIES, strict=True):
        assert line.startswith(f"{name}: as read (lfbench's convention): mean error "), line
    assert lines[4] == (f"lf7 at {root}: 3 of 3 scenes with ground truth agree with lfbench's reading, 0 contradict "
                        "it, 0 undecided; 0 without ground truth")
    rc, out, err = run_cli(capsys, "evaluate", "--data", root, "--method", "gt", "--method", "constant", "--out",
                           tmp_path / "ev", "--no-progress")
    assert rc == 0, err
    results = json.loads((tmp_path / "ev" / "results.json").read_text())
    assert results["meta"]["dataset"] == "lf7" and results["meta"]["scoring"]["border_px"] == 4
    scored = {(r["method"], r["scene"], r["metric"]): r["value"] for r in results["records"]}
    assert {m for _, _, m in scored} == {"badpix_0.07", "mse_x100"}  # the README protocol's metrics, no other
    for name in DISPARITIES:
        assert scored["gt", name, "badpix_0.07"] == 0.0 and scored["gt", name, "mse_x100"] == 0.0
        assert scored["constant", name, "badpix_0.07"] == 100.0  # the constant 0 is |d| = 1 px off everywhere


# --------------------------------------------------------------------------- the contract check's refusals

BROKEN = '''
import dataclasses

import numpy as np
from npy7_plugin import NPY7_PROTOCOL, Npy7Dataset, Npy7Scene


class Broken(Npy7Scene):
{scene}


class BrokenDataset(Npy7Dataset):
    name = "broken7"
    protocol = {protocol}
{dataset}

    @classmethod
    def open(cls, root):
        bench = super().open(root)
        return dataclasses.replace(bench, scenes=tuple({make} for s in bench.scenes))
'''

#: (scene members, protocol, how a scene is made, the problem check-dataset names)
BROKEN_CASES = {
    "view-shape": ("    def load_views(self):\n        return super().load_views()[:, :6]", None, None,
                   "load_views() gave views of shape (7, 6, 16, 16, 3), expected float32 (7, 7, H, W, 3) RGB or "
                   "(7, 7, H, W) gray"),
    "uint8": ("    def load_views(self):\n        return np.load(self.path)", None, None,
              "load_views() gave uint8 views, expected float32 (7, 7, H, W, 3) RGB or (7, 7, H, W) gray in [0, 1]"),
    "above-1": ("    def load_views(self):\n        return np.load(self.path).astype(np.float32)", None, None,
                "load_views() gave values in [0, 255], expected [0, 1] (8-bit: divide by 255)"),
    "nan-views": ("    def load_views(self):\n        views = super().load_views()\n"
                  "        views[0, 0, 0, 0, 0] = np.nan\n        return views", None, None,
                  "load_views() gave 1 NaN or infinite values, expected values in [0, 1]"),
    "raises": ("    def load_views(self):\n        raise ValueError('cannot decode the views')", None, None,
               "load_views() failed: ValueError: cannot decode the views"),
    "spatial-size": ("    @property\n    def spatial_size(self):\n        return (17, 16)", None, None,
                     "spatial_size is (17, 16), its views are (16, 16)"),
    "gt-shape": ("    def gt_disparity(self, resolution='lowres'):\n"
                 "        return super().gt_disparity(resolution)[:-1]", None, None,
                 "gt_disparity() is (15, 16), expected (16, 16) (the views' (H, W))"),
    "gt-all-nan": ("    def gt_disparity(self, resolution='lowres'):\n"
                   "        return np.full(self.spatial_size, np.nan, np.float32)", None, None,
                   "gt_disparity() has no finite value"),
    "highres-gt": ("    def has_gt(self, resolution='lowres'):\n        return True\n\n"
                   "    def gt_disparity(self, resolution='lowres'):\n        gt = np.load(self._gt_path)\n"
                   "        return gt if resolution == 'lowres' else np.kron(gt, np.ones((2, 3), np.float32))",
                   "dataclasses.replace(NPY7_PROTOCOL, resolutions=('lowres', 'highres'))", None,
                   "gt_disparity('highres') is (32, 48), expected (32, 32) (2 times the views' (H, W))"),
    "protocol-angular": ("    pass", "dataclasses.replace(NPY7_PROTOCOL, angular_size=(5, 5))", None,
                         "angular_size is (7, 7), the protocol declares (5, 5)"),
    "no-pickle": ("    def __init__(self, path, category, flag):\n        super().__init__(path, category)\n"
                  "        self.flag = flag", None, "Broken(s.path, s.category, True)",
                  "pickling to a --jobs worker (it is rebuilt as Broken(*reopen_args())) failed: TypeError: "
                  "Broken.__init__() missing 1 required positional argument: 'flag'"),
}


def _npy7_root(root: Path, scenes: dict[str, int]) -> Path:
    """A tests/npy7_plugin.py root of 16x16 px scenes in the category ``val`` (name -> integer disparity)."""
    for seed, (name, d) in enumerate(scenes.items()):
        write_npy7_scene(root, name, "val", shifted_views(_textured(seed, (16, 16)), d, ANGULAR),
                         np.full((16, 16), float(d), np.float32))
    return root


def _install_broken(tmp_path: Path, monkeypatch, scene: str = "    pass", protocol: str | None = None,
                    make: str | None = None, dataset: str = "") -> str:
    """The module (a fresh name: the caller forgets it) of an adapter :data:`BROKEN` with these members, installed
    as the plugin ``broken7``."""
    module = f"broken7_{uuid.uuid4().hex[:8]}"
    site = tmp_path / "site"
    site.mkdir()
    (site / f"{module}.py").write_text(BROKEN.format(scene=scene, protocol=protocol or "NPY7_PROTOCOL", dataset=dataset,
                                                     make=make or "Broken(s.path, s.category)"), encoding="utf-8")
    install_dataset_plugin(site, monkeypatch, "broken7", {"broken7": f"{module}:BrokenDataset"})
    return module


def _refused(capsys, root: Path) -> str:
    """check-dataset's one error line on ``root`` (the same with --adapter-only), nothing on stdout."""
    lines = set()
    for extra in ((), ("--adapter-only",)):
        rc, out, err = run_cli(capsys, "check-dataset", root, "--no-progress", *extra)
        lines.add(assert_one_error_line(rc, err))
        assert out == ""
    (line,) = lines
    return line


@pytest.mark.parametrize("case", list(BROKEN_CASES))
def test_check_dataset_refuses_a_broken_scene_in_one_line(tmp_path, monkeypatch, capsys, case):
    scene, protocol, make, problem = BROKEN_CASES[case]
    module = _install_broken(tmp_path, monkeypatch, scene, protocol, make)
    root = _npy7_root(tmp_path / "npy7", {"val0": 1})
    try:
        assert _refused(capsys, root) == (f"lfbench check-dataset: error: adapter 'broken7' ({module}.BrokenDataset): "
                                          f"scene 'val0' ({root / 'val' / 'val0.views.npy'}): {problem}")
    finally:
        forget_module(module)


@pytest.mark.parametrize(("member", "problem"), [
    ("summary = 'two\\nlines'",
     "'broken7' ({module}.BrokenDataset): summary is 'two\\nlines', expected one line of text"),
    ("name = 'other'", "'other' ({module}.BrokenDataset): is not registered as 'other' (its entry point in the group "
                       "lfbench.datasets must be named as its `name`)"),
], ids=["two-line-summary", "unregistered-name"])
def test_check_dataset_refuses_a_broken_adapter_class_in_one_line(tmp_path, monkeypatch, capsys, member, problem):
    module = _install_broken(tmp_path, monkeypatch, dataset=f"    {member}")
    root = _npy7_root(tmp_path / "npy7", {"val0": 1})
    try:
        assert _refused(capsys, root) == f"lfbench check-dataset: error: adapter {problem.format(module=module)}"
    finally:
        forget_module(module)


def test_the_good_npy7_plugin_passes_the_contract_check(tmp_path, monkeypatch, capsys):
    install_dataset_plugin(tmp_path / "site", monkeypatch, "lfbench-npy7-test", {"npy7": "npy7_plugin:Npy7Dataset"})
    root = _npy7_root(tmp_path / "npy7", {"val0": 1, "val1": -1})
    rc, out, err = run_cli(capsys, "check-dataset", root, "--no-progress", "--adapter-only")
    assert (rc, err) == (0, "")
    assert out == "adapter 'npy7' (npy7_plugin.Npy7Dataset): contract holds on 2 scenes (views and ground truth read " \
                  "on 2)\n"


def test_the_check_reads_views_of_the_first_scenes_only_and_releases_them(tmp_path, monkeypatch):
    from npy7_plugin import Npy7Dataset, Npy7Scene

    from lfbench.data.adapter_check import check_adapter
    from lfbench.data.dataset import open_datasets

    install_dataset_plugin(tmp_path / "site", monkeypatch, "lfbench-npy7-test", {"npy7": "npy7_plugin:Npy7Dataset"})
    root = _npy7_root(tmp_path / "npy7", {f"val{i}": 1 for i in range(5)})
    loaded: list[str] = []
    real = Npy7Scene.load_views

    def load_views(self):
        loaded.append(self.name)
        return real(self)

    monkeypatch.setattr(Npy7Scene, "load_views", load_views)
    dataset, protocol, bench = open_datasets([root])
    assert dataset is Npy7Dataset
    check = check_adapter(dataset, root, protocol, bench.select([]), views_checked=2)
    assert check.holds and (check.scenes, check.views_read) == (5, 2)
    assert loaded == ["val0", "val1"]
    assert all("_views" not in s.__dict__ for s in bench.scenes)
