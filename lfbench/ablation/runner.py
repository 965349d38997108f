"""``lfbench ablate``: run every cell of a spec (resumable, optionally in parallel processes), then
combine their scores into OUT/results.json and the tables and figures (lfbench.ablation.report).

Layout of OUT::

    spec.toml                  the spec as given
    data/<set>/                synthetic training scenes, generated once and linked into each cell
    eval_data/<set>/           synthetic evaluation scenes
    stage1/                    the shared stage-1 run (specs with [stage1] shared = true)
    cells/<cell id>/           one `lfbench train` run per cell, its scores and maps (lfbench.ablation.cell)
    methods/<label>/           scores of the spec's extra [[methods]]
    results.json, results.csv  every cell's and method's records (method = cell id or label)
    table_*.md/.tex/.csv, figures/   see lfbench.ablation.report
    html/                      the HTML report (``html``: lfbench.ablation.report.AblationSite)

spec.toml, results.json, results.csv, the tables, figures and html/ are one output set
(lfbench.utils.outputs), written by the ablation's output writers (lfbench.ablation.report.report_writers)
into a staging folder and committed together, under OUT's results.json.lock, so that a kill or a full
disk leaves the previous set or the new one. Each cell's and extra method's scores and maps are a set of
their own folder (lfbench.runs.folder.evaluate_to_folder with lfbench.reports.writers.Maps).

Re-running the same command skips finished cells (their marker is written last) and resumes an
interrupted one from its training checkpoint.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import os
import shlex
import shutil
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from lfbench.ablation.cell import (
    GENERATED_LAYOUT,
    MAPS,
    CellTask,
    is_done,
    link_data_folder,
    load_scenes,
    open_generated,
    read_marker,
    results_meta,
    run_cell,
    scoring_kwargs,
    scoring_of,
)
from lfbench.ablation.report import check_maps, report_writers, run_writers
from lfbench.ablation.spec import AblationSpec, Cell, SyntheticEval, sha256_of
from lfbench.method.registry import create_from_spec
from lfbench.reports.writers import Maps
from lfbench.results import Results, check_names, check_same_scoring
from lfbench.runs.folder import evaluate_to_folder
from lfbench.training.scenes import check_data
from lfbench.utils.atomic import fresh_dir, write_text
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.executor import ClusterOptions, Executor, executor_for
from lfbench.utils.flags import JOBS
from lfbench.utils.hardware import available_cores
from lfbench.utils.jsonfile import json_text, read_json
from lfbench.utils.log import log_to_file
from lfbench.utils.names import file_name
from lfbench.utils.outputs import (
    OutputSet,
    check_output_entries,
    prepare_output_folder,
    read_manifest,
    recover,
    staged_outputs,
)
from lfbench.utils.readfile import file_sha256
from lfbench.utils.tomlfile import toml_text

Log = Callable[[str], None]
_log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- data

def _generate(target: Path, seed: int, size: int, scenes: int, category: str, log: Log) -> Path:
    """Synthetic scenes as target/<scene>/, generated in a temporary folder and renamed into place."""
    if target.is_dir():
        return target
    from lfbench.data.synth import write_benchmark

    target.parent.mkdir(parents=True, exist_ok=True)
    log(f"generating {scenes} synthetic scenes ({size} px, seed {seed}) into {target}")
    tmp = fresh_dir(target.parent, f".{target.name}.")
    try:
        write_benchmark(tmp, seed=seed, size=size, scenes=scenes, category=category, workers=available_cores())
        os.replace(tmp / category, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return target


def prepare_training_data(cells: tuple[Cell, ...], out: Path, log: Log) -> dict[str, dict[str, str]]:
    """Generate every [[data.synthetic]] set the cells read (DataConfig.synthetic_in_use: not a validation set
    that data.validation = [] leaves unused) once into OUT/data/; returns, per cell id, category -> folder
    (linked into the cell as CELL/data/<category>)."""
    links: dict[str, dict[str, str]] = {}
    for cell in cells:
        links[cell.id] = {}
        for syn in cell.train_config().data.synthetic_in_use():
            folder = _generate(shared_data_folder(out, syn), syn.seed, syn.size, syn.scenes, syn.category, log)
            links[cell.id][syn.category] = str(folder)
    return links


def shared_data_folder(out: Path, syn) -> Path:
    """OUT/data/<set>: where the [[data.synthetic]] set ``syn`` is generated once for every cell."""
    return out / "data" / f"{syn.category}_s{syn.seed}_{syn.size}px_{syn.scenes}"


def stale_links(data_dir: Path, out: Path, cfg) -> set[str]:
    """The categories of ``cfg``'s synthetic sets in use whose link in ``data_dir`` (a cell's or stage 1's data
    folder) leads anywhere but the shared set (OUT/data/<set>): an earlier version's absolute link, a link into
    another folder. They are re-pointed before training (link_data_folder), never followed."""
    stale = set()
    for syn in cfg.data.synthetic_in_use():
        link = data_dir / syn.category
        if link.is_symlink():
            try:
                right = link.resolve(strict=True) == shared_data_folder(out, syn).resolve()
            except (OSError, RuntimeError):  # dangling or a loop
                right = False
            if not right:
                stale.add(syn.category)
    return stale


def check_training_data(spec: AblationSpec, out: Path) -> None:
    """Every cell's data names (roots, train / validation scenes, validation border) checked before anything
    is generated or written (lfbench.training.scenes.check_data; cells with the same data checked once)."""
    seen = set()
    for cell in spec.cells:
        key = json.dumps([cell.config["data"], cell.config["validation"]], sort_keys=True)
        data_dir = out / "cells" / cell.id / "data"
        cfg = cell.train_config(spec.source)
        renew = stale_links(data_dir, out, cfg)
        if (key, tuple(sorted(renew))) not in seen:
            seen.add((key, tuple(sorted(renew))))
            check_data(cfg, data_dir, renew)


def prepare_evaluation(spec: AblationSpec, out: Path, log: Log) -> tuple[tuple[str, str], ...]:
    """The evaluation scenes as (folder, category): generated synthetic ones and/or the named ones of the
    evaluation's data root."""
    from lfbench.data.dataset import DATASETS, open_dataset
    from lfbench.data.scene import Scene, check_scene_names

    ev = spec.evaluation
    scenes: list[Scene] = []
    generated = DATASETS.get(GENERATED_LAYOUT)
    if ev.synthetic is not None:
        syn: SyntheticEval = ev.synthetic
        folder = _generate(out / "eval_data" / syn.folder_name, syn.seed, syn.size, syn.scenes, "synthetic", log)
        scenes += [open_generated(p) for p in sorted(folder.iterdir()) if generated.matches(p)]
    if ev.data is not None:
        if not ev.data.is_dir():
            raise DataError("evaluation.data: data root not found", ev.data)
        dataset, bench = open_dataset(ev.data, ev.dataset)
        if ev.synthetic is not None and dataset.protocol_for(ev.data) != generated.protocol:
            raise SpecError(f"evaluation: synthetic scenes (HCI layout) and {dataset.name} scenes are scored by two "
                            "protocols; one ablation scores one dataset's scenes", spec.source)
        scenes += [s for s in bench.select(list(ev.scenes)) if s.has_gt()]
    if not scenes:
        raise DataError("none of the evaluation scenes has ground truth", spec.source)
    return tuple((str(s.path), s.category) for s in check_scene_names(scenes))


# --------------------------------------------------------------------------- stage 1

def run_shared_stage1(spec: AblationSpec, out: Path, links: dict[str, str], threads: int,
                      progress: bool | None, log: Log) -> Path:
    """Train the shared stages (all but the last) once into OUT/stage1 (resuming when interrupted), under a
    file lock: another ``lfbench ablate`` on the same OUT (e.g. other --cells) waits for it and reuses it."""
    from filelock import FileLock

    folder = out / "stage1"
    folder.mkdir(parents=True, exist_ok=True)
    with FileLock(folder / "stage1.lock"):
        return _shared_stage1(spec, folder, links, threads, progress, log)


def _shared_stage1(spec: AblationSpec, folder: Path, links: dict[str, str], threads: int, progress: bool | None,
                   log: Log) -> Path:
    from lfbench.ablation.cell import LOG, TRAIN_CONFIG
    from lfbench.training.config import TrainConfig, comparable
    from lfbench.training.loop import train

    cfg = spec.stage1_config()
    cfg["training"]["threads"] = threads
    path = folder / TRAIN_CONFIG
    if path.is_file() and comparable(TrainConfig.from_toml(path).to_dict()) != comparable(cfg):
        raise SpecError(f"{path} holds another stage-1 config; use another --out folder")
    write_text(path, toml_text(cfg, f"The shared stage 1 of {spec.source}: written by lfbench ablate."))
    for category, target in links.items():
        link_data_folder(folder / "data" / category, Path(target))
    marker = folder / "done.json"
    if marker.is_file():
        return folder
    log(f"stage 1 (shared by {len(spec.cells)} cells) in {folder}")
    command = shlex.join(["lfbench", "train", str(path), "--out", str(folder)])
    with log_to_file(folder / LOG):  # train() restores the caller's thread count itself
        train(TrainConfig.from_toml(path), folder, command=command, progress=progress)
    summary = read_json(folder / "summary.json", "training summary")
    write_text(marker, json_text({"steps": summary["steps"], "elapsed_s": summary["elapsed_s"]}, indent=2) + "\n")
    return folder


# --------------------------------------------------------------------------- cells

def evaluation_angular(spec: AblationSpec, scenes: tuple[tuple[str, str], ...]) -> tuple[int, int]:
    """(V, U) views of the evaluation scenes (what every cell is scored and timed on), checked against the
    network of every cell before anything trains: SpecError naming the spec when the scenes differ in angular
    size or a cell's network takes another (its ``angular``, from a build on PyTorch's meta device)."""
    from lfbench.training.model import model_angular

    sizes = {tuple(s.angular_size) for s in load_scenes(scenes, spec.evaluation)}
    if len(sizes) != 1:
        raise SpecError("evaluation: the scenes differ in angular size ("
                        + ", ".join(f"{u}x{v}" for v, u in sorted(sizes)) + "); one ablation scores one size",
                        spec.source)
    v, u = sizes.pop()
    for cell in spec.cells:
        angular = model_angular(cell.train_config(spec.source))
        if (angular, angular) != (v, u):
            raise SpecError(f"cell {cell.id}: its network takes {angular}x{angular} views, the evaluation scenes have "
                            f"{u}x{v}: no cell is trained", spec.source)
    return v, u


def make_tasks(spec: AblationSpec, out: Path, links: dict[str, dict[str, str]], scenes: tuple[tuple[str, str], ...],
               threads: int, stage1: Path | None, progress: bool | None,
               angular: tuple[int, int] = (9, 9)) -> list[CellTask]:
    tasks = []
    for cell in spec.cells:
        config = json.loads(json.dumps(cell.config))
        config["training"]["threads"] = threads
        tasks.append(CellTask(
            cell_id=cell.id, values=cell.values, config=config, fingerprint=cell.fingerprint,
            eval_fingerprint=sha256_of([spec.evaluation.fingerprint(), scene_keys(scenes, out)]),
            cell_dir=str(out / "cells" / cell.id), data_links=links[cell.id],
            stage1_dir=str(stage1) if stage1 is not None else None, scenes=scenes, evaluation=spec.evaluation,
            threads=threads, progress=progress, angular=angular))
    return tasks


def scene_keys(scenes: tuple[tuple[str, str], ...], out: Path) -> list[str]:
    """The evaluation scenes as fingerprints name them: a scene generated inside OUT by its path relative to OUT
    (``OUT/eval_data/...``), so that a folder moved or copied as a whole keeps its finished cells; any other by
    its path as given."""
    root = out.resolve()
    keys = []
    for folder, _ in scenes:
        path = Path(folder).resolve()
        keys.append("OUT/" + path.relative_to(root).as_posix() if path.is_relative_to(root) else folder)
    return keys


def _cost_estimate(task: CellTask) -> float:
    """Relative cost of a cell, to start the longest first: its network's estimate for the steps the cell
    trains itself (``Trainable.cost_estimate``), else those steps."""
    from lfbench.method.trainable import get_trainable

    steps = sum(int(s["steps"]) for s in task.config["stages"][(1 if task.stage1_dir else 0):])
    cost = get_trainable(task.network).cost_estimate(dict(task.config["model"]), steps)
    return float(steps if cost is None else cost)


def run_cells(tasks: list[CellTask], executor: Executor, progress: bool | None, log: Log) -> list[dict[str, Any]]:
    """Run the unfinished cells through ``executor`` (lfbench.utils.executor: in this process, ``--jobs``
    worker processes each with its own GPU, or one submitit job per cell); returns every cell's marker."""
    from tqdm import tqdm

    pending = [t for t in tasks if not is_done(t, warn=False)]  # run_cell says why a cell is re-made
    for t in tasks:
        if t not in pending:
            log(f"cell {t.cell_id}: finished earlier, skipped")
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(pending), desc="cells", unit="cell",
               disable=None if progress is None else not progress, file=sys.stderr, dynamic_ncols=True)

    def done(marker: dict[str, Any]) -> None:
        _report(marker, log)
        bar.update(1)

    try:
        if pending:
            here = executor.runs_here(len(pending))
            cells = pending if here else [replace(t, progress=False) for t in pending]
            executor.map(run_cell, cells, labels=[f"cell {t.cell_id}" for t in cells], threads=cells[0].threads,
                         on_done=done, on_start=lambda label: bar.set_postfix_str(label.removeprefix("cell ")[-50:]),
                         cost=_cost_estimate)
    finally:
        bar.close()
    return [read_marker(t.cell_dir) or {} for t in tasks]


def _report(marker: dict[str, Any], log: Log) -> None:
    log(f"cell {marker.get('id')}: trained {marker.get('steps')} steps in {marker.get('train_s', float('nan')):.1f} s"
        f" (own {marker.get('own_train_s', float('nan')):.1f} s), scored on {len(marker.get('scenes', []))} scene(s)")


def time_cells(tasks: list[CellTask], threads: int, progress: bool | None, log: Log,
               executor: Executor) -> list[dict[str, Any]]:
    """Test time of every finished cell, one at a time (cached in CELL/timing.json), as one item of
    ``executor``: in this process, or (an executor that submits jobs) in one job on a cell's resources, so
    that the time is that of the device the cells ran on, not of the machine that submitted them (e.g. a
    login node without a GPU)."""
    from tqdm import tqdm

    timings: list[dict[str, Any]] = []
    if tasks:
        batch = tasks
        if executor.runs_here(1):
            batch = tqdm(tasks, desc="test time", unit="cell", file=sys.stderr, leave=False,
                         disable=None if progress is None else not progress)
        executor.map(functools.partial(_time_all, threads=threads), [batch], labels=["test time"], threads=threads,
                     on_done=timings.extend)
    for t, timing in zip(tasks, timings, strict=True):
        v, u = t.angular
        side = timing["time_size"]
        log(f"cell {t.cell_id}: test time {timing['test_s']:.2f} s for {u}x{v}x{side}x{side}"
            f" ({timing['device']}, {threads} thread{'s' if threads != 1 else ''})")
    return timings


def _time_all(tasks, threads: int) -> list[dict[str, Any]]:
    """:func:`lfbench.ablation.cell.time_cell` of each task, one after the other."""
    from lfbench.ablation.cell import time_cell

    return [time_cell(t.cell_dir, t.evaluation, threads, t.network, t.angular) for t in tasks]


# --------------------------------------------------------------------------- extra methods

def run_methods(spec: AblationSpec, out: Path, scenes: tuple[tuple[str, str], ...], log: Log) -> list[Results]:
    """Score the spec's [[methods]] (cached in OUT/methods/<label>/ with a marker, like cells)."""

    ev = spec.evaluation
    scoring, grid = scoring_kwargs(ev), scoring_of(ev).grid  # the protocol's rules, metrics and method grid
    loaded = load_scenes(scenes, ev)
    out_list = []
    for m in spec.methods:
        folder = out / "methods" / file_name(m.label)
        method = create_from_spec(m.spec, {}, grid)
        # the method's files (weights) by content: other weights under the same path are another method
        content = {k: v["sha256"] for k, v in method.provenance().items() if isinstance(v, dict)}
        key = sha256_of([m.spec, content, ev.fingerprint(), scene_keys(scenes, out)])
        marker = folder / "method.json"
        done = read_json(marker, "method marker") if marker.is_file() else None
        if isinstance(done, dict) and done.get("key") == key:
            changed = _results_changed(folder, done)
            if changed is None:
                out_list.append(Results.read(folder))
                log(f"method {m.label}: finished earlier, skipped")
                continue
            log(f"method {m.label}: {changed}; scored again")
        res = evaluate_to_folder([method], loaded, folder, rules=scoring["rules"], metrics=scoring["metrics"],
                                 label=m.label, writers=[Maps(MAPS, per_method=False, uncertainty=True)],
                                 progress=False, meta={**scoring["meta"],
                                                       "method": {"label": m.label, "spec": m.spec}})
        if res.records:  # a method that served no scene (e.g. weights not there yet) is tried again next time
            record = {"label": m.label, "spec": m.spec, "key": key,
                      "results_sha256": file_sha256(folder / "results.json", "method results")}
            write_text(marker, json_text(record, indent=2) + "\n")
        log(f"method {m.label}: scored on {len(res.scenes)} scene(s)")
        out_list.append(res)
    return out_list


def _results_changed(folder: Path, marker: dict[str, Any]) -> str | None:
    """Why ``folder``'s results.json is not the one its marker recorded (``results_sha256``), or None."""
    path = folder / "results.json"
    try:
        digest = file_sha256(path, "method results")
    except DataError as exc:
        return str(exc)
    return None if digest == marker.get("results_sha256") else f"{path} is not the file its method.json recorded"


# --------------------------------------------------------------------------- the whole run

@dataclass
class AblationRun:
    out: Path
    results: Results
    markers: list[dict[str, Any]]
    written: list[Path]


def run_ablation(spec: AblationSpec, out: str | Path, *, jobs: int = 1, progress: bool | None = None,
                 paper: str | Path | None = None, log: Log = _log.info,
                 cluster: ClusterOptions | None = None, html: bool = False, maps: str = "all") -> AblationRun:
    """Run (or resume) every cell and extra method of ``spec`` into ``out``; write the combined results,
    tables and figures (and, with ``html``, the HTML report) as one set. ``paper``: the paper's tables
    folder (None: lfbench.reports.paper.find_paper_dir). ``cluster``: run the cells as submitit jobs (see
    lfbench.utils.executor). OUT/results.json is merged under a file lock: runs of different cells
    (``--cells``, several processes or machines) add up. ``maps``: whose saved maps the error-map figures and
    the site draw (lfbench.ablation.report.MAP_CHOICES: all, best, none)."""
    JOBS.require(jobs)  # a call from Python; the command line has checked it as it parsed it
    check_maps(maps)
    out = Path(out)
    executor = executor_for(cluster, jobs=jobs, folder=out / "submitit", log=log)
    executor.check()  # before any work: no data generated, nothing submitted
    check_folders(spec, out)  # what is re-used from OUT resolves inside it, before anything is read
    check_training_data(spec, out)
    prepare_output_folder(out)
    check_output_entries(out)
    with _set_lock(out):
        recover(out)  # a cut commit of an earlier run is finished (or its journal refused) before any work
        read_manifest(out)
    cores = available_cores()
    per_job = executor.cpus_per_item  # a cluster job's CPUs, not this machine's cores
    threads = spec.budget.threads or per_job or max(1, cores // jobs)
    log(f"{spec.title}: {len(spec.cells)} cell(s), {len(spec.methods)} extra method(s), budget "
        f"{spec.budget_label()}; {jobs} process(es) x {threads} thread(s) on {cores} core(s)")
    scenes = prepare_evaluation(spec, out, log)
    angular = evaluation_angular(spec, scenes)  # a network that cannot take the scenes: refused before any training
    links = prepare_training_data(spec.cells, out, log)
    stage1 = None
    if spec.shared_stage1 and spec.cells:
        stage1 = run_shared_stage1(spec, out, links[spec.cells[0].id], spec.budget.threads or cores, progress, log)
    tasks = make_tasks(spec, out, links, scenes, threads, stage1, progress, angular)
    markers = run_cells(tasks, executor, progress, log)
    timings = time_cells(tasks, spec.evaluation.threads or per_job or cores, progress, log, executor)
    markers = [{**m, **{k: v for k, v in t.items() if k != "key"}} for m, t in zip(markers, timings, strict=True)]
    combined = Results(meta={**results_meta(spec.evaluation),
                             **({"synthetic": True} if spec.evaluation.is_synthetic else {}),
                             "ablation": {"title": spec.title, "spec": str(spec.source), "table": spec.table,
                                          "budget": spec.budget_label(), "shared_stage1": spec.shared_stage1,
                                          "cells": markers}})
    for t in tasks:
        cell = Results.read(Path(t.cell_dir))  # the folder: its results.json may not lead out of it
        check_same_scoring(combined, cell, Path(t.cell_dir) / "results.json")
        combined.extend(cell)
    references = []
    for res in run_methods(spec, out, scenes, log):
        check_same_scoring(combined, res, out / "methods")
        combined.extend(res)
        references += res.meta.get("references", [])  # an oracle among the [[methods]]: a reference line
    combined.meta["references"] = references
    combined.meta["scenes"] = [s for s, _ in scenes]
    with _set_lock(out), staged_outputs(out) as outputs:
        merged = merge_results(out, combined, outputs.stage)
        if spec.text:
            write_text(outputs.stage / "spec.toml", spec.text)
        written = _write_set(spec, out, outputs, combined, markers, paper=paper, html=html, log=log, scenes=scenes,
                             maps=maps)
    if len(merged.methods) > len(combined.methods):
        log(f"{out / 'results.json'}: {len(combined.methods)} of {len(merged.methods)} cells/methods from this run "
            "(the others from earlier runs); `lfbench ablate SPEC --report-only` tabulates them all")
    return AblationRun(out=out, results=combined, markers=markers, written=written)


def check_folders(spec: AblationSpec, out: Path) -> None:
    """DataError when a folder the run trains, scores or generates into (stage1, cells/<id>, methods/<label>,
    data, eval_data, submitit), or anything below one of them (a cell's data folder, its checkpoint, maps, ...),
    leads out of OUT through a symbolic link: an ablation reads and writes inside OUT only. The links of a
    data folder to the synthetic sets in use (CELL/data/<category>, stage1/data/<category>) are exempt: one that
    leads elsewhere is re-pointed (link_data_folder), never followed. Checked before anything is read or written."""
    from lfbench.utils.outputs import check_within

    if not out.is_dir():
        return
    names = ["cells", "methods", "stage1", "data", "eval_data", "submitit"]
    names += [f"cells/{c.id}" for c in spec.cells] + [f"methods/{file_name(m.label)}" for m in spec.methods]
    for name in names:
        if (out / name).is_symlink():
            check_within(out / name, out, "the ablation folder")
    in_use = {c.id: {s.category for s in c.train_config(spec.source).data.synthetic_in_use()} for c in spec.cells}
    relinked = {out / "cells" / cid / "data" / cat for cid, cats in in_use.items() for cat in cats}
    relinked |= {out / "stage1" / "data" / cat for cats in in_use.values() for cat in cats}
    trees = ["stage1", "data", "eval_data"] + [f"cells/{c.id}" for c in spec.cells]
    trees += [f"methods/{file_name(m.label)}" for m in spec.methods]
    for tree in trees:
        if not (out / tree).is_dir():
            continue
        for folder, dirs, files in os.walk(out / tree):  # links are listed, never followed
            for entry in (*dirs, *files):
                path = Path(folder) / entry
                if path.is_symlink() and path not in relinked:
                    check_within(path, out, "the ablation folder")


def _set_lock(out: Path):
    """The lock under which OUT's set (results.json, tables, figures, html) is read, merged and committed."""
    from filelock import FileLock

    return FileLock(out / "results.json.lock")


def _write_set(spec: AblationSpec, out: Path, outputs: OutputSet, results: Results, markers: list[dict[str, Any]], *,
               paper: str | Path | None, html: bool, log: Log, keep: tuple[str, ...] = (),
               scenes: tuple[tuple[str, str], ...] | None = None, maps: str = "all") -> list[Path]:
    """The ablation's writers (tables, figures and, with ``html``, the site, drawn from the staged
    results.json) into the staging folder, then the commit of the staged entries; returns the final paths
    of what the writers wrote. ``scenes``: the evaluation scenes (prepared here when None and the site needs
    them); ``maps``: whose saved maps are drawn (lfbench.ablation.report.drawn_map_folders)."""
    stage = outputs.stage
    writers = report_writers(spec, markers, results, paper=paper, folder=out, html=html, log=log, maps=maps)
    site_scenes = (load_scenes(scenes if scenes is not None else prepare_evaluation(spec, out, log), spec.evaluation)
                   if html else ())
    staged = run_writers(writers, spec, results, stage, out, site_scenes, maps=maps)
    books = [stage / name for name in ("results.json", "results.csv", "spec.toml") if (stage / name).is_file()]
    written = outputs.commit_written([*staged, *books], keep=keep)[:len(staged)]
    log(f"wrote {len(written)} files into {out} (results.json, table_*.md/.tex/.csv, figures/)")
    return written


def merge_results(out: Path, new: Results, dest: Path | None = None) -> Results:
    """OUT/results.json's records of other cells/methods plus ``new`` (whose cells/methods replace theirs),
    the ablation's cell markers merged by id, written into ``dest`` (default OUT). Called under OUT's
    results.json.lock (``_set_lock``) so that concurrent runs of different cells do not lose each other's
    results. Returns what was written."""
    path = out / "results.json"
    dest = out if dest is None else dest
    if not path.is_file():
        new.write(dest)
        return new
    old = Results.read(out)
    check_same_scoring(new, old, path)  # earlier runs' cells are tabulated beside these: one protocol
    replaced = set(new.methods)
    merged = Results(records=[r for r in old.records if r.method not in replaced] + list(new.records),
                     runs=[r for r in old.runs if r.method not in replaced] + list(new.runs),
                     meta=dict(new.meta))
    new_cells = new.meta.get("ablation", {}).get("cells", [])
    ids = {m.get("id") for m in new_cells}
    old_cells = [m for m in old.meta.get("ablation", {}).get("cells", []) if m.get("id") not in ids]
    if "ablation" in merged.meta:
        merged.meta["ablation"] = {**merged.meta["ablation"], "cells": old_cells + list(new_cells)}
    merged.meta["scenes"] = sorted(set(old.meta.get("scenes", [])) | set(new.meta.get("scenes", [])))
    check_names(merged.methods, merged.scenes, source=path)  # earlier runs' cells beside this run's: the set's names
    merged.write(dest)
    return merged


def report_only(spec: AblationSpec, out: str | Path, *, paper: str | Path | None = None,
                log: Log = _log.info, html: bool = False, maps: str = "all") -> list[Path]:
    """Rewrite the tables and figures (and, with ``html``, the site) from OUT/results.json and the cells'
    markers (nothing is run), as one set that keeps results.json. A cell whose folder is gone (e.g. a
    results/ copy that keeps only results.json) uses the marker that results.json recorded for it, so the
    tables of a committed run can be rebuilt from its results.json."""
    check_maps(maps)
    out = Path(out)
    with _set_lock(out) if out.is_dir() else contextlib.nullcontext():
        return _report_only(spec, out, paper=paper, log=log, html=html, maps=maps)


def _report_only(spec: AblationSpec, out: Path, *, paper: str | Path | None, log: Log, html: bool,
                 maps: str = "all") -> list[Path]:
    from lfbench.ablation.cell import TIMING

    recover(out)  # a cut commit is finished (or a journal that is not lfbench's refused) before reading
    read_manifest(out)
    results = Results.read(out if out.is_dir() else out / "results.json")  # a folder: no link out of it
    recorded = {m.get("id"): m for m in results.meta.get("ablation", {}).get("cells", []) if isinstance(m, dict)}
    markers = []
    for c in spec.cells:
        marker = read_marker(out / "cells" / c.id) or {}
        timing = out / "cells" / c.id / TIMING
        if marker and timing.is_file():
            marker.update({k: v for k, v in read_json(timing, "cell timing").items() if k != "key"})
        markers.append(marker or dict(recorded.get(c.id, {})))
    missing = [c.id for c, m in zip(spec.cells, markers, strict=True) if "test_s" not in m]
    if missing:
        raise DataError(f"cell(s) not finished: {', '.join(missing)}; run `lfbench ablate` first", out)
    results.meta["scenes"] = evaluation_scene_dirs(spec, out, results.meta.get("scenes", []))
    with staged_outputs(out) as outputs:
        return _write_set(spec, out, outputs, results, markers, paper=paper, html=html, log=log,
                          keep=("results.json", "results.csv", "spec.toml"), maps=maps)


def evaluation_scene_dirs(spec: AblationSpec, out: Path, recorded: list[Any]) -> list[str]:
    """The scene folders a results.json records (``meta.scenes``) that are scenes of the spec's evaluation:
    a path read back from a results file is used only when the spec names it (generated under
    OUT/eval_data, or a scene of the evaluation's data root)."""
    ev = spec.evaluation
    roots = []
    if ev.synthetic is not None:
        roots.append((out / "eval_data" / ev.synthetic.folder_name).resolve())
    if ev.data is not None:
        roots.append(Path(ev.data).resolve())
    kept = []
    for item in recorded:
        if isinstance(item, str) and any(Path(item).resolve().is_relative_to(r) for r in roots):
            kept.append(item)
    return kept
