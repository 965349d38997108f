"""Tiny HCI-format scenes and submissions for tests (no real data needed).

A scene written by :func:`write_scene` has 9x9 RGB views of ``size`` x ``size`` px that are exact
integer shifts of one random texture (a fronto-parallel plane at ``view_disparity`` px per view step,
following the benchmark's geometry: centre(x, y) = view_{u,v}(x - (u-4) d, y - (v-4) d)), a
parameters.cfg written by :meth:`SceneParameters.to_cfg`, and gt_disp_lowres.pfm (and optionally
gt_disp_highres.pfm at 10x) written by :func:`write_pfm`.
"""

from __future__ import annotations

import importlib.util
import io
import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
from PIL import Image

from lfbench.data.hci.params import SceneParameters
from lfbench.data.pfm import write_pfm

ANGULAR = 9
EXAMPLE_PLUGIN = Path(__file__).resolve().parent.parent / "examples" / "tiny_plugin"


def scene_parameters(name: str, category: str, size: int, angular: int = ANGULAR) -> SceneParameters:
    """Camera parameters like the HCI scenes' (f = 100 mm, sensor 35 mm, b = 30 mm, F = 8.3 m)."""
    return SceneParameters(
        focal_length_mm=100.0, image_resolution_x_px=size, image_resolution_y_px=size, sensor_size_mm=35.0,
        num_cams_x=angular, num_cams_y=angular, baseline_mm=30.0, focus_distance_m=8.3,
        disp_min=-2.0, disp_max=2.0, depth_map_scale=10.0, name=name, category=category,
    )


def shifted_views(centre: np.ndarray, d: int, angular: int = ANGULAR) -> np.ndarray:
    """(V, U, H, W, C) views of a plane at integer disparity ``d``: view_{u,v}(x, y) = centre(x + (u-c) d, y + (v-c) d)
    (periodic at the image edge)."""
    c = angular // 2
    rows = []
    for v in range(angular):
        rows.append([np.roll(centre, (-(v - c) * d, -(u - c) * d), axis=(0, 1)) for u in range(angular)])
    return np.asarray(rows)


def write_scene(root: Path, name: str = "tiny", category: str = "training", *, size: int = 40, seed: int = 0,
                view_disparity: int = 1, gt: np.ndarray | None = None, gt_highres: np.ndarray | None = None,
                views: bool = True, masks: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write an HCI scene folder ROOT/<category>/<name>/ and return its path.

    gt: (size, size) low-res disparity (default: the plane at ``view_disparity``); gt_highres:
    (10 size, 10 size) written as gt_disp_highres.pfm when given; masks: {'<name>_lowres': bool (H, W)}.
    """
    rng = np.random.default_rng(seed)
    folder = Path(root) / category / name
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "parameters.cfg").write_text(scene_parameters(name, category, size).to_cfg(), encoding="utf-8")
    if views:
        centre = rng.integers(0, 256, size=(size, size, 3), dtype=np.uint8)
        stack = shifted_views(centre, view_disparity)
        for k in range(ANGULAR * ANGULAR):
            Image.fromarray(stack[k // ANGULAR, k % ANGULAR]).save(folder / f"input_Cam{k:03d}.png")
    if gt is None:
        gt = np.full((size, size), float(view_disparity), dtype=np.float32)
    write_pfm(folder / "gt_disp_lowres.pfm", np.asarray(gt, dtype=np.float32))
    if gt_highres is not None:
        write_pfm(folder / "gt_disp_highres.pfm", np.asarray(gt_highres, dtype=np.float32))
    for mask_name, mask in (masks or {}).items():
        Image.fromarray(np.where(mask, 255, 0).astype(np.uint8)).save(folder / f"{mask_name}.png")
    return folder


def write_submission(root: Path, maps: Mapping[str, np.ndarray], runtimes: Mapping[str, str] | None = None) -> Path:
    """A submission folder: disp_maps/<scene>.pfm from ``maps``, runtimes/<scene>.txt (text, default '1.5')."""
    root = Path(root)
    for scene, disp in maps.items():
        write_pfm(root / "disp_maps" / f"{scene}.pfm", np.asarray(disp, dtype=np.float32))
    for scene in maps:
        text = (runtimes or {}).get(scene, "1.5\n")
        (root / "runtimes").mkdir(parents=True, exist_ok=True)
        (root / "runtimes" / f"{scene}.txt").write_text(text, encoding="utf-8")
    return root


def zip_folder(folder: Path, zip_path: Path, prefix: str = "",
               extra: Iterable[tuple[str | zipfile.ZipInfo, bytes]] = ()) -> Path:
    """Zip every file under ``folder`` as ``prefix + relative path``, plus ``extra`` (name or ZipInfo, bytes)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(Path(folder).rglob("*")):
            if p.is_file():
                zf.write(p, prefix + p.relative_to(folder).as_posix())
        for name, data in extra:
            zf.writestr(name, data)
    Path(zip_path).write_bytes(buf.getvalue())
    return Path(zip_path)


def pfm_bytes(data: np.ndarray, *, ident: bytes = b"Pf", big_endian: bool = False, scale: float = 1.0) -> bytes:
    """A PFM file built by hand (independent of lfbench.data.pfm): rows bottom-up, sign of scale = byte order."""
    arr = np.asarray(data, dtype=np.float32)
    h, w = arr.shape[:2]
    dtype = ">f4" if big_endian else "<f4"
    signed = abs(scale) if big_endian else -abs(scale)
    payload = np.ascontiguousarray(arr[::-1], dtype=dtype).tobytes()
    return ident + b"\n" + f"{w} {h}\n".encode() + f"{signed}\n".encode() + payload


PLUGIN_MODULE = '''\
"""A third-party lfbench plugin used by the tests."""
from lfbench.method.base import Method, Prediction
from lfbench.method.registry import register_method


@register_method("{centre}")
class CentreView(Method):
    """Returns the centre view times ``gain`` as its 'disparity' (a test plugin).

    gain: factor applied to the centre view
    """

    def __init__(self, gain: float = 1.0) -> None:
        super().__init__(gain=gain)
        self.gain = gain

    def predict(self, lf):
        v, u = lf.angular_size
        return Prediction(disparity=lf.gray_views()[v // 2, u // 2] * self.gain)


class Offset(Method):
    """Ground truth plus a constant (registered by its entry point, not by a decorator).

    offset: added to the ground truth, px
    """

    def __init__(self, offset: float = 0.0) -> None:
        super().__init__(offset=offset)
        self.offset = offset

    def predict(self, lf):
        return Prediction(disparity=lf.gt_disparity() + self.offset)
'''


def write_dist_info(site: Path, name: str, entry_points: str) -> Path:
    """An installed distribution's ``<name>-1.0.dist-info`` under ``site`` (put on sys.path), its
    ``entry_points.txt`` holding ``entry_points`` (e.g. ``"[lfbench.commands]\nx = module\n"``)."""
    dist = site / f"{name.replace('-', '_')}-1.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n", encoding="utf-8")
    (dist / "entry_points.txt").write_text(entry_points, encoding="utf-8")
    return dist


def write_fake_plugin(root: Path, tag: str) -> dict[str, str]:
    """A fake installed distribution under ``root`` (put it on sys.path / PYTHONPATH): a module and a
    ``*.dist-info`` whose entry_points.txt adds methods to the ``lfbench.methods`` group.

    Returns the names: module, centre (a decorated class, module entry point), offset (a factory entry
    point) and broken (an entry point whose module does not exist).
    """
    names = {"module": f"lfbench_testplugin_{tag}", "centre": f"centre-{tag}", "offset": f"offset-{tag}",
             "broken": f"broken-{tag}"}
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    (root / f"{names['module']}.py").write_text(PLUGIN_MODULE.format(centre=names["centre"]), encoding="utf-8")
    dist = root / f"lfbench_testplugin_{tag}-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: lfbench-testplugin-{tag}\nVersion: 1.0\n",
                                   encoding="utf-8")
    (dist / "entry_points.txt").write_text(
        "[lfbench.methods]\n"
        f"{names['centre']} = {names['module']}\n"
        f"{names['offset']} = {names['module']}:Offset\n"
        f"{names['broken']} = {names['module']}_does_not_exist\n", encoding="utf-8")
    return names


def isolate_registries(monkeypatch) -> None:
    """Let the process-wide method and trainable registries take what a test registers (and load entry
    points added since they were filled: the installed plugins were loaded when the session started, see
    conftest.pytest_sessionstart), and forget it afterwards (undone by ``monkeypatch``)."""
    import lfbench.method.registry as registry
    import lfbench.method.trainable as trainable

    for reg in (registry.REGISTRY, trainable.TRAINABLES):
        for attr in ("_objects", "_entries", "_aliases", "load_errors"):
            monkeypatch.setattr(reg, attr, dict(getattr(reg, attr)))
        monkeypatch.setattr(reg, "_loaded", False)


def install_dataset_plugin(site: Path, monkeypatch, dist: str, entry_points: Mapping[str, str]) -> None:
    """A dataset adapter plugin installed as pip would (no pip): a distribution ``dist`` under ``site`` (put on
    sys.path) whose ``lfbench.datasets`` entry points are ``entry_points`` (name -> ``module:Class``), and the
    datasets registry isolated so that it loads them (and forgets them afterwards: ``monkeypatch``)."""
    import lfbench.data.dataset as dataset

    lines = "".join(f"{name} = {target}\n" for name, target in entry_points.items())
    write_dist_info(site, dist, f"[lfbench.datasets]\n{lines}")
    monkeypatch.syspath_prepend(str(site))
    reg = dataset.DATASETS
    for attr in ("_objects", "_entries", "_aliases", "load_errors"):
        monkeypatch.setattr(reg, attr, dict(getattr(reg, attr)))
    monkeypatch.setattr(reg, "_loaded", False)


def install_fake_plugin(site: Path, monkeypatch) -> dict[str, str]:
    """Write a fake plugin distribution into ``site``, put it on sys.path and isolate the registries
    (:func:`isolate_registries`; the caller drops the module from sys.modules afterwards: see
    :func:`forget_module`)."""
    import uuid

    names = write_fake_plugin(site, uuid.uuid4().hex[:10])
    monkeypatch.syspath_prepend(str(site))
    isolate_registries(monkeypatch)
    return names


def forget_module(name: str) -> None:

    sys.modules.pop(name, None)


def run_cli(capsys, *args) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``lfbench ARGS`` run in-process (argparse exits become codes)."""
    from lfbench.cli import main

    try:
        rc = main([str(a) for a in args])
    except SystemExit as exc:
        rc = exc.code
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_error_line(rc: int, err: str, *fragments: str) -> str:
    """The CLI's promise for bad input: exit 2, exactly one stderr line holding every fragment, no traceback."""
    assert rc == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def install_package(src: Path, site: Path) -> None:
    """``pip install SRC --target SITE`` (no network: --no-index, --no-deps, no build isolation); where
    setuptools is absent (venvs of Python >= 3.12), the same distribution written by hand: the packages
    the pyproject lists and a dist-info with its entry points."""
    import shutil
    import sys

    if importlib.util.find_spec("setuptools") is not None:
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                        "--no-index", "--target", str(site), str(src)], check=True, capture_output=True)
        return
    pyproject = tomllib.loads((src / "pyproject.toml").read_text())
    project = pyproject["project"]
    for package in pyproject["tool"]["setuptools"]["packages"]:
        shutil.copytree(src / package, site / package)
    dist = site / f"{project['name'].replace('-', '_')}-{project['version']}.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n")
    lines = [f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items())
             for group, eps in project["entry-points"].items()]
    (dist / "entry_points.txt").write_text("\n".join(lines))


def example_grid() -> str:
    """The example plugin's ablation (examples/tiny_plugin/ablate_channels.toml: channels 4 and 8, 20 + 5 steps,
    1 thread) with every cell once per seed 1 and 2: 4 cells of seconds each (base: train_tiny.toml beside it)."""
    text = (EXAMPLE_PLUGIN / "ablate_channels.toml").read_text()
    base = 'base = "train_tiny.toml"\n'
    assert base in text
    return text.replace(base, base + "seeds = [1, 2]\n")


def example_copy(folder: Path) -> Path:
    """examples/tiny_plugin copied to ``folder`` (its sources and specs, no build outputs), for a test to change."""
    shutil.copytree(EXAMPLE_PLUGIN, folder, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    return folder


def install_example_plugin(tmp: Path) -> tuple[Path, Path, dict[str, str]]:
    """examples/tiny_plugin copied to tmp/src and installed into tmp/site the way a user installs it: pip install
    --target (no network: --no-index, --no-deps, no build isolation); where setuptools is absent (venvs of
    Python >= 3.12), the same distribution written by hand (the package and a dist-info with the pyproject's
    entry points). Returns (src, site, an environment whose PYTHONPATH holds site, one OpenMP thread)."""
    src, site = example_copy(tmp / "src"), tmp / "site"
    install_package(src, site)
    assert (site / "lfbench_tiny" / "plugin.py").is_file()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(site), os.environ.get("PYTHONPATH")) if p),
           "OMP_NUM_THREADS": "1"}
    return src, site, env


README = Path(__file__).resolve().parent.parent / "README.md"


def readme_section(heading: str) -> str:
    """The README's ``## heading`` section, up to the next ``## `` heading."""
    text = README.read_text(encoding="utf-8")
    start = text.index(f"## {heading}")
    return text[start:text.index("\n## ", start + 3)]


def code_blocks(section: str) -> list[tuple[str, str]]:
    """(language, body) of every fenced code block of ``section``."""
    return [(m[1], m[2]) for m in re.finditer(r"```(\w*)\n(.*?)```", section, re.S)]


def as_plugin(fn, qualname: str, module: str = "hostile_plugin"):
    """``fn`` as a plugin's function: its ``__module__`` ``module`` and ``__qualname__`` ``qualname`` (so that the
    error lines naming it are written out whole)."""
    fn.__module__ = module
    fn.__qualname__ = qualname
    return fn


def _no_module(self):
    raise AttributeError("__module__")


class Anonymous:
    """A callable object with neither ``__module__`` nor ``__qualname__`` (a plugin may hand over such a thing):
    calls ``then(*args, **kwargs)``."""

    __module__ = property(_no_module)

    def __init__(self, then=None) -> None:
        self.then = then

    def __call__(self, *args, **kwargs):
        return self.then(*args, **kwargs)
