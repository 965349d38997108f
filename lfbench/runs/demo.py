"""``lfbench demo``: a mini benchmark that needs no dataset and no network.

Generates synthetic light fields (lfbench.data.synth, HCI layout with exact ground truth) under
OUT/data/, runs every registered method that can run offline on them, scores them as the benchmark
does, and writes OUT/results.json, OUT/results.csv, the tables (table_per_scene.*, table_average.*),
the figures (OUT/figures/), every method's disparity maps (OUT/maps/<method>/, submission layout) and
the HTML report (OUT/html/index.html; ``lfbench report OUT --out REP --html`` draws it again from those
files). Results, tables, figures, maps and the report are one output set (lfbench.utils.outputs).

Re-running into the same folder reuses the generated data when it was made with the same seed,
size and number of scenes (OUT/data/demo.json records them) and refuses otherwise: data of two
settings are never mixed. Results, tables, figures, maps and report of a re-run replace the old ones.
"""

from __future__ import annotations

import inspect
import json
import logging
import os
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from lfbench.utils.atomic import fresh_dir
from lfbench.utils.errors import DataError, LFBenchError, SpecError
from lfbench.utils.jsonfile import read_json

MANIFEST = "demo.json"
DATA_DIR = "data"  # the other folders are named by their writers (lfbench.reports.writers, maps, html)
CATEGORY = "synthetic"
DEFAULT_SEED, DEFAULT_SIZE, DEFAULT_SCENES = 0, 128, 4

Log = Callable[[str], None]
_log = logging.getLogger(__name__)
# The layers above (data generation, methods, scoring, writers) are imported where they are used: `lfbench`
# builds every command's parser at start-up, and the demo's reads this module's defaults.


@dataclass
class DemoOutcome:
    """What a demo run produced: the results, the methods run and skipped (name -> reason), files."""

    results: object
    methods: list[str]
    skipped: dict[str, str]
    files: dict[str, Path] = field(default_factory=dict)
    reused_data: bool = False


# --------------------------------------------------------------------------- data

def data_settings(seed: int, size: int, scenes: int) -> dict:
    """What identifies a generated demo data set (stored in OUT/data/demo.json)."""
    from lfbench.data.synth import GENERATOR_VERSION

    return {"generator": f"lfbench.data.synth v{GENERATOR_VERSION}", "seed": int(seed), "size": int(size),
            "scenes": int(scenes), "category": CATEGORY}


def _describe(s: dict) -> str:
    return f"seed={s.get('seed')}, size={s.get('size')}, scenes={s.get('scenes')} ({s.get('generator')})"


def prepare_data(out: Path, seed: int, size: int, scenes: int, log: Log = _log.info) -> tuple[Path, bool]:
    """The demo's data root OUT/data, generated now or reused. Returns (root, reused).

    Refuses (DataError) a folder holding data of other settings, or a non-empty folder that is not
    a demo folder. Data are generated into a temporary folder (manifest included) and renamed into
    place when complete, so an interrupted run leaves nothing that a later run would reuse.
    """
    from lfbench.data.synth import check_args

    check_args(size)  # before any message or folder
    out = Path(out)
    root = out / DATA_DIR
    wanted = data_settings(seed, size, scenes)
    manifest = root / MANIFEST
    if root.is_symlink():
        from lfbench.utils.outputs import check_within

        check_within(root, out, "the demo folder")
    if manifest.is_file():
        try:
            stored = read_json(manifest, "demo manifest")
        except DataError as exc:
            raise DataError(f"unreadable: {exc}; remove {out} or choose another --out") from None
        if not isinstance(stored, dict) or stored.get("settings") != wanted:
            got = stored.get("settings", {}) if isinstance(stored, dict) else {}
            raise DataError(f"holds demo data generated with {_describe(got)}, not {_describe(wanted)}; "
                            "choose another --out or remove this folder (data of two settings are never mixed)", out)
        from lfbench.data.dataset import DATASETS
        from lfbench.data.synth import SYNTH_LAYOUT

        generated = DATASETS.get(SYNTH_LAYOUT)  # the adapter of the layout the demo data are written in
        scene_dirs = stored.get("scene_dirs")
        if not isinstance(scene_dirs, list) or not all(_inside(root, s) for s in scene_dirs):
            raise DataError("demo manifest: scene_dirs must list scene folders inside the data folder", manifest)
        missing = [s for s in scene_dirs if not (root / s).is_dir() or not generated.matches(root / s)]
        if missing or not scene_dirs:
            raise DataError(f"demo data are incomplete (missing {', '.join(missing) or 'scene list'}); "
                            "remove this folder or choose another --out", out)
        log(f"reusing the demo data in {root} ({_describe(wanted)})")
        return root, True
    if out.exists() and not out.is_dir():
        raise DataError("exists and is not a folder", out)
    if out.is_dir() and any(p for p in out.iterdir() if not p.name.startswith(".")):
        raise DataError("folder is not empty and holds no lfbench demo (no data/demo.json); "
                        "choose another --out", out)
    from lfbench.data.synth import write_benchmark

    out.mkdir(parents=True, exist_ok=True)
    tmp = fresh_dir(out, f".{DATA_DIR}.", ".tmp")
    try:
        log(f"generating {scenes} synthetic scene(s) of {size}x{size} px, seed {seed}, into {root}")
        dirs = write_benchmark(tmp, seed=seed, size=size, scenes=scenes, category=CATEGORY)
        rel = [str(Path(d).relative_to(tmp)) for d in dirs]
        (tmp / MANIFEST).write_text(json.dumps({"settings": wanted, "scene_dirs": rel}, indent=2) + "\n",
                                    encoding="utf-8")
        os.replace(tmp, root)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return root, False


def _inside(root: Path, rel: object) -> bool:
    """Whether ``rel`` (read from demo.json) names a folder inside ``root``: relative, no '..', and not
    leading out through a symbolic link."""
    if not isinstance(rel, str) or not rel or Path(rel).is_absolute() or ".." in Path(rel).parts:
        return False
    path = root / rel
    return not path.exists() or path.resolve().is_relative_to(root.resolve())


# --------------------------------------------------------------------------- methods

def split_specs(text: str) -> list[str]:
    """Split ``--methods`` text on commas, keeping ``key=value`` pieces with the spec before them:
    'gt,planesweep:interval=0.5,interpolation=nearest' -> ['gt', 'planesweep:interval=0.5,interpolation=nearest']."""
    specs: list[str] = []
    for piece in (p.strip() for p in text.split(",")):
        if not piece:
            continue
        if "=" in piece and ":" not in piece and specs:
            specs[-1] += "," + piece
        else:
            specs.append(piece)
    return specs


def select_methods(requested: Sequence | None, scenes: Sequence, log: Log = _log.info) -> tuple[list, dict[str, str]]:
    """The methods to run and the skipped ones (name -> one-line reason).

    Without ``requested`` methods: every registered method whose parameters all have defaults
    (``published`` needs a path: skipped) and that runs on every scene (``available_for`` gives no
    reason); a method offering ``offline_variants()`` (e.g. the architecture of its shipped weights)
    runs as those variants. With ``requested`` (methods made from the user's
    specs): those; one that cannot run on the scenes is skipped with its reason.
    """
    from lfbench.method.registry import REGISTRY, create, list_methods, offline_variants

    candidates: list = []
    skipped: dict[str, str] = {}
    if requested:
        candidates = list(requested)
    else:
        for info in list_methods():
            required = [p.name for p in info.params.values() if p.default is inspect.Parameter.empty]
            if required:
                skipped[info.name] = f"needs parameter {', '.join(required)} (e.g. {info.name}:{required[0]}=...)"
                continue
            for params in offline_variants(info.name):  # e.g. the shipped weights' architecture
                try:
                    candidates.append(create(info.name, **params))
                except LFBenchError as exc:
                    skipped[info.name] = str(exc)
        for name, error in sorted(REGISTRY.load_errors.items()):
            skipped.setdefault(name, f"plugin failed to load ({error})")
    methods = []
    for method in candidates:
        reason = next((r for r in (method.available_for(s) for s in scenes) if r is not None), None)
        if reason is None:
            methods.append(method)
        else:
            skipped[method.label] = reason
    for name, reason in skipped.items():
        log(f"skipping {name}: {' '.join(str(reason).split())}")
    if not methods:
        raise SpecError("no method can run on the demo scenes" + (f" ({'; '.join(skipped.values())})"
                                                                  if skipped else ""))
    return methods, skipped


# --------------------------------------------------------------------------- the run

def run_demo(out: str | Path = "lfbench-demo", *, seed: int = DEFAULT_SEED, size: int = DEFAULT_SIZE,
             scenes: int = DEFAULT_SCENES, methods: Sequence[str] | None = None, figures: bool = True,
             html: bool = True, progress: bool = True, log: Log = _log.info) -> DemoOutcome:
    """Generate (or reuse) the demo data under ``out``, run and score the methods and write results,
    tables, figures, every method's maps (OUT/maps) and, with ``html``, the HTML report (OUT/html), as one
    set (lfbench.runs.folder.evaluate_to_folder with the writers of lfbench.reports.writers).
    Returns a :class:`DemoOutcome`."""
    from lfbench.data.dataset import DATASETS
    from lfbench.data.synth import SYNTH_LAYOUT
    from lfbench.method.registry import create_from_spec
    from lfbench.reports.html import SITE_DIR
    from lfbench.reports.maps import MAPS_DIR
    from lfbench.reports.writers import FIGURES_DIR, Maps, SceneFigures, Site, Tables
    from lfbench.runs.folder import evaluate_to_folder
    from lfbench.utils.outputs import read_manifest, recover

    if int(scenes) != scenes or scenes < 1:
        raise SpecError(f"--scenes must be a positive integer, got {scenes}")
    out = Path(out)
    requested = [create_from_spec(s) for s in methods] if methods else None  # spec errors before any work
    if out.is_dir():  # a cut commit is finished, or a journal or manifest that is not lfbench's refused, first
        recover(out)
        read_manifest(out)
    root, reused = prepare_data(out, seed, size, scenes, log)
    scene_list = [s for s in DATASETS.get(SYNTH_LAYOUT).open(root) if s.has_gt()]
    chosen, skipped = select_methods(requested, scene_list, log)
    writers = [*([SceneFigures()] if figures else []), Maps(), Tables(), *([Site()] if html else [])]
    results = evaluate_to_folder(chosen, scene_list, out, writers=writers, progress=progress,
                                 meta={"data_root": str(root), "demo": data_settings(seed, size, scenes),
                                       "skipped_methods": skipped})
    files: dict[str, Path] = {"results.json": out / "results.json", "results.csv": out / "results.csv",
                              "tables": out, "data": root, "maps": out / MAPS_DIR}
    if figures:
        files["figures"] = out / FIGURES_DIR
    if html:
        files["html"] = out / SITE_DIR / "index.html"
    return DemoOutcome(results=results, methods=[m.label for m in chosen], skipped=skipped, files=files,
                       reused_data=reused)
