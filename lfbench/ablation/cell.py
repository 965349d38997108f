"""One ablation cell: train it (``lfbench train`` in-process, resuming from its own checkpoint), score
its final weights on the evaluation scenes with the method that runs the network's checkpoints
(``lfbench.method.registry.network_runner``; ``subfocal`` for SubFocal), and write the marker
``cell.json`` last (atomically): a cell with a marker of the same config is finished and is not run
again, as long as its ``final.pt`` and ``results.json`` are the files the marker recorded (else it is re-made).
The test time (one whole-scene prediction) is measured afterwards by :func:`time_cell`, one cell at a time, so
that parallel cells do not slow each other's timings.

Files in OUT/cells/<cell id>/ (besides the trainer's checkpoint.pt, final.pt, metrics.jsonl,
summary.json, ...): ``train.toml`` (the cell's training config: ``lfbench train train.toml --out
CELL`` reproduces it), ``log.txt`` (the trainer's log lines), ``results.json`` / ``results.csv``
(its scores, method = the cell id), ``maps/`` (disparity and uncertainty maps in the submission
layout), ``cell.json`` and ``timing.json``.

A cell of a spec with a shared stage 1 starts from the shared run's final checkpoint: it is copied
in with the cell's config (the trainer's own resume then runs the last stage only), so the result is
bit for bit that of an uninterrupted two-stage ``lfbench train`` of ``train.toml``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shlex
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfbench.ablation.spec import Evaluation
from lfbench.data.synth import SYNTH_LAYOUT
from lfbench.method.trainable import DEFAULT_TRAINABLE
from lfbench.utils.atomic import write_bytes, write_text
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.jsonfile import json_text, read_json
from lfbench.utils.log import log_to_file
from lfbench.utils.readfile import file_sha256, read_bytes
from lfbench.utils.threads import torch_threads
from lfbench.utils.tomlfile import toml_text

MARKER, TRAIN_CONFIG, LOG, MAPS, TIMING = "cell.json", "train.toml", "log.txt", "maps", "timing.json"
MAX_COPY_BYTES = 4 * 1024**3  # a shared stage-1 export copied into a cell (weights of at most 2 GiB, its log)
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CellTask:
    """Everything a worker process needs to run one cell (plain, picklable values)."""

    cell_id: str
    values: dict[str, Any]
    config: dict[str, Any]
    fingerprint: str
    eval_fingerprint: str
    cell_dir: str
    data_links: dict[str, str]  # synthetic category -> shared folder of generated scenes
    stage1_dir: str | None
    scenes: tuple[tuple[str, str], ...]  # (scene folder, category)
    evaluation: Evaluation
    threads: int
    progress: bool | None = None
    angular: tuple[int, int] = (9, 9)  # (V, U) views of the evaluation scenes: the light field the cell is timed on

    @property
    def path(self) -> Path:
        return Path(self.cell_dir)

    @property
    def network(self) -> str:
        """The registered trainable network the cell trains."""
        return self.config.get("method", DEFAULT_TRAINABLE)


def read_marker(cell_dir: str | Path) -> dict[str, Any] | None:
    """The cell's marker (None when absent or unreadable: a cell without one is not finished)."""
    try:
        marker = read_json(Path(cell_dir) / MARKER, "cell marker")
    except DataError:
        return None
    return marker if isinstance(marker, dict) else None


def is_done(task: CellTask, *, warn: bool = True) -> bool:
    """True when the cell finished with this config and these evaluation settings, and its artefacts are the
    ones its marker recorded: ``final.pt`` holds the weights of ``final_sha256`` and ``results.json`` the bytes
    of ``results_sha256`` (a file copied over from another cell, or changed, makes the cell unfinished: it is
    re-made, its weights re-exported from its own training checkpoint, its scores re-made; one log line says
    which file differed). A marker of another training config is a SpecError (the folder holds another
    experiment). ``warn``: log the line (the run that re-makes the cell does)."""
    marker = read_marker(task.cell_dir)
    if marker is None:
        return False
    if marker.get("fingerprint") != task.fingerprint:
        raise SpecError(f"cell {task.cell_id} in {task.cell_dir} was trained with another config; use another "
                        "--out folder (or delete that cell folder)")
    if marker.get("eval_fingerprint") != task.eval_fingerprint:
        return False
    changed = recorded_mismatch(task.path, marker)
    if changed is not None:
        if warn:
            _log.warning("cell %s: %s; the cell is re-made", task.cell_id, changed)
        return False
    return True


def recorded_mismatch(cell_dir: Path, marker: dict[str, Any]) -> str | None:
    """Why the cell's ``final.pt`` or ``results.json`` is not what its ``marker`` recorded (None when both are)."""
    final, results = cell_dir / "final.pt", cell_dir / "results.json"
    for path, key, digest in ((results, "results_sha256", _file_digest), (final, "final_sha256", weights_digest)):
        try:
            actual = digest(path)
        except DataError as exc:
            return str(exc)
        if actual != marker.get(key):
            return f"{path} is not the file the cell recorded ({key})"
    return None


def _file_digest(path: Path) -> str:
    return file_sha256(path, "cell results")


def write_train_config(task: CellTask) -> Path:
    """Write CELL/train.toml (unchanged if present with the same config; SpecError if it differs)."""
    from lfbench.training.config import TrainConfig, comparable

    path = task.path / TRAIN_CONFIG
    header = (f"Ablation cell {task.cell_id}: written by lfbench ablate.\n"
              f"Reproduce: lfbench train {path} --out {task.path}")
    text = toml_text(task.config, header)
    if path.is_file():
        old = TrainConfig.from_toml(path).to_dict()
        if comparable(old) != comparable(task.config):
            raise SpecError(f"cell {task.cell_id}: {path} holds another config; use another --out folder")
    write_text(path, text)
    return path


def link_data(task: CellTask) -> None:
    """Make CELL/data/<category> point at the shared generated scenes (the trainer then skips
    generating them); without symlink support each cell generates its own copy."""
    for category, folder in task.data_links.items():
        link_data_folder(task.path / "data" / category, Path(folder))


def link_data_folder(link: Path, target: Path) -> None:
    """Make ``link`` a relative symbolic link to the generated scenes ``target`` (so that an ablation folder
    moved or copied as a whole still resumes). A link that leads elsewhere (an absolute one of a folder that
    was moved, or any other) is replaced by the right one, never followed; a real folder (a copy made where
    symbolic links are not supported) is kept. Without symlink support nothing is linked."""
    if link.is_symlink():
        try:
            if link.resolve(strict=True) == target.resolve():
                return
        except (OSError, RuntimeError):  # dangling or a loop: replaced
            pass
        link.unlink()
    elif link.exists():
        return
    link.parent.mkdir(parents=True, exist_ok=True)
    with contextlib.suppress(OSError):
        link.symlink_to(os.path.relpath(target.resolve(), link.parent.resolve()), target_is_directory=True)


def seed_from_stage1(task: CellTask) -> float:
    """Put the shared run's final checkpoint (next stage = the last, step 0, no optimizer) into the cell
    with the cell's config, unless the cell has a checkpoint already. Returns the stage-1 seconds."""
    from lfbench.training import checkpoint as ckpt
    from lfbench.training.run_folder import stage_weights_name

    assert task.stage1_dir is not None
    src = Path(task.stage1_dir)
    state = ckpt.load(src / "checkpoint.pt", ckpt.CHECKPOINT_FORMAT)
    n_shared = len(task.config["stages"]) - 1
    if state["stage"] != n_shared or state["step"] != 0:
        raise DataError(f"the shared stage-1 run is not finished (stage {state['stage']}, step {state['step']})",
                        src / "checkpoint.pt")
    dst = task.path / "checkpoint.pt"
    if not dst.is_file():
        names = [stage_weights_name(i, s["name"]) for i, s in enumerate(task.config["stages"][:n_shared])]
        for name in [*names, "best.pt", "metrics.jsonl"]:
            if (src / name).is_file():
                write_bytes(task.path / name, read_bytes(src / name, name, MAX_COPY_BYTES))
        state["config"] = task.config
        ckpt.save(dst, state)  # last: its presence means "seeded"
    return float(state["elapsed_s"])


def stage1_digest(stage1_dir: str | Path) -> str:
    """SHA-256 of the model state the shared run ended with (what every cell's last stage starts from)."""
    from lfbench.training import checkpoint as ckpt

    state = ckpt.load(Path(stage1_dir) / "checkpoint.pt", ckpt.CHECKPOINT_FORMAT)
    return ckpt.state_sha256(state["model"])


# --------------------------------------------------------------------------- evaluation

def resolve_device(name: str) -> str:
    """The evaluation device as the tables name it: ``cpu``, ``cuda`` (for auto / cuda) or ``cuda:K``;
    SpecError (lfbench.utils.hardware.resolve_device) for one this machine lacks."""
    from lfbench.utils.hardware import resolve_device as hardware_device

    dev = hardware_device(name)
    return dev.type if name in ("auto", "cuda") else str(dev)


def make_method(weights: Path, ev: Evaluation, threads: int, network: str = DEFAULT_TRAINABLE):
    """The method running these weights of the trainable ``network`` (lfbench.method.registry.network_runner),
    on the evaluation device, with the evaluation's threads, tile, memory budget and precision where it has them."""
    from lfbench.method.registry import network_runner

    return network_runner(network, weights, device=resolve_device(ev.device), threads=threads, tile=ev.tile,
                          max_memory_gb=ev.max_memory_gb, precision=ev.precision)


def time_whole_scene(method, size: int, repeats: int, warmup: int, seed: int = 0,
                     angular: tuple[int, int] = (9, 9)) -> list[float]:
    """Seconds of ``repeats`` predictions of one whole V x U x size x size light field (``angular`` = (V, U):
    the evaluation scenes' views; random views: the network's cost does not depend on the content), after
    ``warmup`` untimed ones."""
    from lfbench.data.scene import ArrayLightField

    rng = np.random.default_rng(seed)
    v, u = angular
    lf = ArrayLightField(views=rng.random((v, u, size, size), dtype=np.float32), name=f"timing_{size}px")
    for _ in range(warmup):
        method.predict(lf)
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        method.predict(lf)
        _sync()
        out.append(time.perf_counter() - start)
    return out


def _sync() -> None:
    import torch

    if torch.cuda.is_available():
        torch.cuda.synchronize()


#: The dataset layout of the ablation's generated scenes (lfbench.data.synth writes them; this adapter reads them).
GENERATED_LAYOUT = SYNTH_LAYOUT


def open_generated(folder: str | Path):
    """One generated scene folder, opened by the adapter of :data:`GENERATED_LAYOUT` (DataError naming the
    folder when it is not one)."""
    from lfbench.data.dataset import DATASETS

    return DATASETS.get(GENERATED_LAYOUT).open(Path(folder)).scenes[0]


def load_scenes(pairs: tuple[tuple[str, str | None], ...], ev: Evaluation | None = None):
    """The scenes of (folder, category) pairs: those under the evaluation's data root opened by its dataset
    adapter (lfbench.data.dataset), the others (generated ones) by :func:`open_generated`."""
    opened = {}
    if ev is not None and ev.data is not None:
        from lfbench.data.dataset import open_dataset

        opened = {str(s.path): s for s in open_dataset(ev.data, ev.dataset)[1].scenes}
    return [opened.get(path) or open_generated(path) for path, _ in pairs]


def evaluation_dataset(ev: Evaluation):
    """The dataset adapter of the evaluation's data root (given or detected); None for generated scenes alone."""
    if ev.data is None:
        return None
    from lfbench.data.dataset import dataset_of

    return dataset_of(ev.data, ev.dataset)


def scoring_of(ev: Evaluation):
    """How the cells and extra methods are scored (lfbench.scoring.protocol.Scoring: rules, metrics and the method
    grid), by the protocol of the dataset of the evaluation's data root, as ``lfbench evaluate`` scores it;
    generated scenes alone by the protocol of the adapter of their layout (:data:`GENERATED_LAYOUT`)."""
    from lfbench.data.dataset import DATASETS
    from lfbench.scoring.protocol import protocol_scoring

    dataset = evaluation_dataset(ev)
    protocol = DATASETS.get(GENERATED_LAYOUT).protocol if dataset is None else dataset.protocol_for(ev.data)
    return protocol_scoring(protocol, allow_highres=not ev.lowres_only)


def scoring_kwargs(ev: Evaluation) -> dict[str, Any]:
    """``evaluate_to_folder``'s rules, metrics and meta of :func:`scoring_of`."""
    from lfbench.results import protocol_meta

    scoring = scoring_of(ev)
    dataset = evaluation_dataset(ev)
    protocol = scoring.protocol  # what the pages show: its metrics and disparity range
    meta = {**({"dataset": dataset.name} if dataset is not None else {}), **scoring.meta(),
            "protocol": protocol_meta(protocol.metrics, protocol.disparity_range)}
    return {"rules": scoring.rules, "metrics": list(scoring.metrics), "meta": meta}


def results_meta(ev: Evaluation) -> dict[str, Any]:
    """What the ablation's merged results record of the evaluation's protocol, as ``lfbench evaluate`` records it:
    the dataset, the protocol's metrics and disparity range (:func:`scoring_kwargs`) and its scoring rules
    (``meta.scoring``: the border the tables, figures and pages follow)."""
    scoring = scoring_kwargs(ev)
    return {**scoring["meta"], "scoring": scoring["rules"].to_meta()}


def evaluate_weights(label: str, weights: Path, ev: Evaluation, scenes, threads: int, out: Path,
                     save_maps: bool = True, network: str = DEFAULT_TRAINABLE):
    """Score the weights (of the trainable ``network``) on the scenes into ``out`` (results.json/csv and,
    with ``save_maps``, the maps with their uncertainty in OUT/maps, as one set); the records are named
    ``label``."""
    from lfbench.reports.writers import Maps
    from lfbench.runs.folder import evaluate_to_folder

    return evaluate_to_folder([make_method(weights, ev, threads, network)], scenes, out, label=label,
                              writers=[Maps(MAPS, per_method=False, uncertainty=True)] if save_maps else [],
                              progress=False, **scoring_kwargs(ev))


def timing_key(ev: Evaluation, threads: int, angular: tuple[int, int] = (9, 9)) -> dict[str, Any]:
    return {"time_size": ev.time_size, "angular": list(angular), "repeats": ev.time_repeats,
            "warmup": ev.time_warmup, "threads": threads, "device": resolve_device(ev.device), "tile": ev.tile,
            "max_memory_gb": ev.max_memory_gb, "precision": ev.precision}


def time_cell(cell_dir: str | Path, ev: Evaluation, threads: int, network: str = DEFAULT_TRAINABLE,
              angular: tuple[int, int] = (9, 9)) -> dict[str, Any]:
    """Test time of a finished cell (CELL/timing.json, reused when the timing settings are the same):
    the median of ``time_repeats`` whole-scene predictions of ``angular`` (V, U) views, the evaluation scenes'.
    Run one cell at a time, with nothing else of the ablation running, so that the cells' times compare."""
    path = Path(cell_dir) / TIMING
    weights = Path(cell_dir) / "final.pt"
    recorded = (read_marker(cell_dir) or {}).get("final_sha256")
    if weights_digest(weights) != recorded:  # the weights timed are the ones the cell scored
        raise DataError("not the weights the cell recorded (final_sha256 of its cell.json); run lfbench ablate "
                        "again to re-make the cell", weights)
    key = {**timing_key(ev, threads, angular), "final_sha256": recorded}
    with contextlib.suppress(DataError):
        old = read_json(path, "cell timing")
        if isinstance(old, dict) and old.get("key") == key:
            return old
    with torch_threads(None):  # the method sets its own count; restore ours afterwards
        method = make_method(weights, ev, threads, network)
        times = time_whole_scene(method, ev.time_size, ev.time_repeats, ev.time_warmup, angular=angular)
    out = {"key": key, "test_s": float(np.median(times)), "test_s_all": times, "time_size": ev.time_size,
           "time_angular": list(angular),
           "threads": threads, "device": key["device"], "host": socket.gethostname(),
           "slurm_job_id": os.environ.get("SLURM_JOB_ID")}
    write_text(path, json_text(out, indent=2, sort_keys=True) + "\n")
    return out


# --------------------------------------------------------------------------- the cell

def run_cell(task: CellTask) -> dict[str, Any]:
    """Train, evaluate and mark one cell (skipped when it is finished); returns its marker. Under a file lock
    in the cell's folder: two ablate processes (or cluster jobs) never train the same cell at once; the
    second finds it finished."""
    from filelock import FileLock

    task.path.mkdir(parents=True, exist_ok=True)
    with FileLock(task.path / "cell.lock"):
        if is_done(task):
            return read_marker(task.cell_dir) or {}
        with torch_threads(task.threads):
            return _run(task)


def _run(task: CellTask) -> dict[str, Any]:
    from lfbench.training import loop
    from lfbench.training.config import TrainConfig

    task.path.mkdir(parents=True, exist_ok=True)
    config_path = write_train_config(task)
    link_data(task)
    stage1_s = 0.0
    if task.stage1_dir is not None:
        stage1_s = seed_from_stage1(task)
    cfg = TrainConfig.from_toml(config_path)
    command = shlex.join(["lfbench", "train", str(config_path), "--out", str(task.path)])
    with log_to_file(task.path / LOG, f"# {time.strftime('%Y-%m-%d %H:%M:%S')} cell {task.cell_id} "
                                      f"({task.threads} threads)"):
        loop.train(cfg, task.path, command=command, progress=task.progress)
    summary = read_json(task.path / "summary.json", "training summary")
    train_s = float(summary["elapsed_s"])

    scenes = load_scenes(task.scenes, task.evaluation)
    results = evaluate_weights(task.cell_id, task.path / "final.pt", task.evaluation, scenes,
                               task.evaluation.threads or task.threads, task.path, True, task.network)
    marker: dict[str, Any] = {
        "id": task.cell_id, "values": task.values, "fingerprint": task.fingerprint,
        "eval_fingerprint": task.eval_fingerprint, "steps": int(summary["steps"]),
        "train_s": train_s, "own_train_s": train_s - stage1_s, "stage1_s": stage1_s,
        "stage1_sha256": stage1_digest(task.stage1_dir) if task.stage1_dir else None,
        "final_sha256": weights_digest(task.path / "final.pt"),
        "threads": task.threads, "device": resolve_device(task.evaluation.device),
        "eval_runtime_s": float(np.mean([r.runtime_s for r in results.runs])) if results.runs else None,
        "scenes": results.scenes,
    }
    results.meta["cell"] = {k: v for k, v in marker.items() if k not in ("fingerprint", "eval_fingerprint")}
    results.write(task.path)
    marker["results_sha256"] = _file_digest(task.path / "results.json")  # what a later run re-uses, checked
    write_text(task.path / MARKER, json_text(marker, indent=2, sort_keys=True) + "\n")
    return marker


def weights_digest(path: Path) -> str:
    """:func:`lfbench.training.checkpoint.state_sha256` of the weights file's state dict (the marker's
    ``final_sha256``); DataError naming the file when it is not weights."""
    from lfbench.training import checkpoint as ckpt

    payload = ckpt.load(path)
    if not isinstance(payload.get("state_dict"), dict):
        raise DataError("not exported weights (no state_dict)", path)
    return ckpt.state_sha256(payload["state_dict"])
