"""Training curves: loggers the training loop calls with every entry it writes to ``metrics.jsonl``.

- :class:`TensorBoardLogger` writes TensorBoard event files into the run folder (view them with
  ``tensorboard --logdir RUN``): ``train/loss``, ``train/learning_rate``, ``train/steps_per_s``,
  ``validation/badpix`` (BadPix at the config's threshold, %), ``validation/mse_x100`` and the same
  per validation scene (``validation/<scene>/badpix``), against the global step. On resume the
  events after the checkpoint's step are purged, as the JSON log's entries are.
- :class:`LearningCurveLogger` draws ``learning_curve.png`` from ``metrics.jsonl`` when the run
  stops (finished or interrupted): the training loss (log scale, stage boundaries dotted) and the
  validation BadPix and MSE against the global step.

A logger is made for one run folder and has ``record(entry)`` and ``close()``; only the main
process calls them. TensorBoard is optional (``pip install lfbench[tensorboard]``): without it
:func:`default_loggers` says so in one line and the run writes its JSON log and PNG curve only.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

from lfbench.utils.figure_text import plain_log_ticks, plain_text
from lfbench.utils.readfile import read_text

__all__ = ["LEARNING_CURVE", "LearningCurveLogger", "RunLogger", "TensorBoardLogger", "default_loggers",
           "plot_learning_curve", "read_metrics", "tensorboard_available"]

log = logging.getLogger(__name__)

LEARNING_CURVE = "learning_curve.png"
MAX_LOG_BYTES = 256 * 1024**2  # metrics.jsonl / command.txt read back from a run folder
TRAIN_SCALARS = (("loss", "train/loss"), ("lr", "train/learning_rate"), ("steps_per_s", "train/steps_per_s"))
VALIDATION_SCALARS = (("badpix", "validation/badpix"), ("mse_x100", "validation/mse_x100"))


class RunLogger(Protocol):
    """What the training loop calls: record every metrics.jsonl entry, close when the run stops."""

    def record(self, entry: dict[str, Any]) -> None: ...

    def close(self) -> None: ...


def tensorboard_available() -> bool:
    try:
        import tensorboard  # noqa: F401
        from torch.utils.tensorboard import SummaryWriter  # noqa: F401
    except ImportError:
        return False
    return True


class TensorBoardLogger:
    """Scalars of every metrics.jsonl entry into TensorBoard event files in the run folder ``out``."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self._writer = None

    def record(self, entry: dict[str, Any]) -> None:
        step = int(entry.get("global_step", 0))
        if self._writer is None:
            from torch.utils.tensorboard import SummaryWriter

            # Opened at the first entry of this process: purge_step drops the events at and after it
            # that a killed run wrote past its last checkpoint (log steps are deterministic, so they
            # are written again), as metrics.jsonl drops its entries.
            self._writer = SummaryWriter(log_dir=str(self.out), purge_step=step)
        if entry.get("event") == "train":
            for key, tag in TRAIN_SCALARS:
                if isinstance(entry.get(key), (int, float)):
                    self._writer.add_scalar(tag, float(entry[key]), step)
        elif entry.get("event") == "validation":
            for key, tag in VALIDATION_SCALARS:
                if isinstance(entry.get(key), (int, float)):
                    self._writer.add_scalar(tag, float(entry[key]), step)
            for scene, values in (entry.get("scenes") or {}).items():
                for key, _ in VALIDATION_SCALARS:
                    if isinstance(values.get(key), (int, float)):
                        self._writer.add_scalar(f"validation/{scene}/{key}", float(values[key]), step)
        self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None


class LearningCurveLogger:
    """Draws OUT/learning_curve.png from OUT/metrics.jsonl when the run stops (if it logged anything)."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self._seen = False

    def record(self, entry: dict[str, Any]) -> None:
        self._seen = True

    def close(self) -> None:
        metrics = self.out / "metrics.jsonl"
        if self._seen and metrics.is_file():
            entries = read_metrics(metrics)
            if any(e.get("event") == "train" for e in entries):
                path = plot_learning_curve(entries, self.out / LEARNING_CURVE, title=self.out.name)
                log.info("learning curve: %s (TensorBoard: tensorboard --logdir %s)", path, self.out)


def default_loggers(out: str | Path) -> list[RunLogger]:
    """The loggers of ``lfbench train`` and ``lfbench ablate`` for run folder ``out``: TensorBoard
    (when installed) and the PNG learning curve."""
    loggers: list[RunLogger] = [LearningCurveLogger(out)]
    if tensorboard_available():
        loggers.insert(0, TensorBoardLogger(out))
    else:
        log.info("note: tensorboard is not installed, so no TensorBoard event files are written "
                 "(pip install 'lfbench[tensorboard]'); metrics.jsonl and learning_curve.png are")
    return loggers


def read_metrics(path: str | Path) -> list[dict[str, Any]]:
    """The entries of a metrics.jsonl (lines that do not parse, e.g. cut by a kill, are skipped)."""
    entries = (parse_log_line(line) for line in read_text(path, "training log", MAX_LOG_BYTES,
                                                          errors="replace").splitlines())
    return [e for e in entries if e is not None]


def parse_log_line(line: str) -> dict[str, Any] | None:
    """One metrics.jsonl entry, or None for a line that is not a JSON object (cut by a kill, or not
    lfbench's: json's own limits, e.g. 5000-digit integers or deep nesting, included)."""
    try:
        entry = json.loads(line)
    except (ValueError, RecursionError):
        return None
    return entry if isinstance(entry, dict) else None


def _number(value: Any) -> float:
    """A logged number as float: null (how metrics.jsonl writes a NaN) or a missing one is NaN."""
    return float(value) if isinstance(value, int | float) else float("nan")


def _validation_labels(val: Sequence[dict[str, Any]]) -> tuple[str, str]:
    """The labels of the validation entries' ``badpix`` and ``mse_x100`` (lfbench.scoring.base.Metric.label): the
    BadPix metric of the entries' ``threshold`` where they record one, else the family's name with its unit."""
    from lfbench.scoring.metrics import get_metric

    threshold = val[-1].get("threshold")
    if isinstance(threshold, int | float) and not isinstance(threshold, bool) and threshold > 0:
        badpix = get_metric(f"badpix_{threshold:g}").label
    else:
        family = get_metric("badpix_0.07")  # the family's name and unit; the entries do not say its threshold
        badpix = f"BadPix ({family.unit})"
    return badpix, get_metric("mse_x100").label


@plain_text
def plot_learning_curve(entries: Sequence[dict[str, Any]], path: str | Path, title: str = "") -> Path:
    """Training loss (log scale; one colour per stage, boundaries dotted) and validation BadPix (%) and
    MSE x100 against the global step, as a PNG."""
    from lfbench.reports.plotting import pyplot, save_figure

    plt = pyplot()
    train = [e for e in entries if e.get("event") == "train"]
    val = [e for e in entries if e.get("event") == "validation"]
    fig, (ax_loss, ax_val) = plt.subplots(1, 2, figsize=(10.5, 3.8))
    stages: dict[Any, list[dict[str, Any]]] = {}
    for e in train:
        stages.setdefault((e.get("stage"), e.get("stage_name")), []).append(e)
    for (stage, name), es in stages.items():
        ax_loss.plot([e["global_step"] for e in es], [_number(e.get("loss")) for e in es], linewidth=1.4, marker="o",
                     markersize=2.5, label=f"stage {stage} {name or ''}".strip())
    for es in list(stages.values())[1:]:
        ax_loss.axvline(es[0]["global_step"], color="0.6", linestyle=":", linewidth=1)
    if train and all(_number(e.get("loss")) > 0 for e in train):
        ax_loss.set_yscale("log")
        plain_log_ticks(ax_loss.yaxis)
    ax_loss.set_xlabel("global step")
    ax_loss.set_ylabel("training loss")
    ax_loss.grid(alpha=0.3)
    if stages:
        ax_loss.legend(fontsize=7)
    if val:
        steps = [e["global_step"] for e in val]
        badpix, mse = _validation_labels(val)
        ax_val.plot(steps, [_number(e.get("badpix")) for e in val], marker="o", markersize=3, color="tab:red",
                    label=badpix)
        ax_val.set_ylabel(f"validation {badpix}", color="tab:red")
        twin = ax_val.twinx()
        twin.plot(steps, [_number(e.get("mse_x100")) for e in val], marker="s", markersize=3, color="tab:blue",
                  label=mse)
        twin.set_ylabel(f"validation {mse}", color="tab:blue")
    else:
        ax_val.text(0.5, 0.5, "no validation", ha="center", va="center", color="0.4", transform=ax_val.transAxes)
    ax_val.set_xlabel("global step")
    ax_val.grid(alpha=0.3)
    fig.suptitle(f"Learning curve {title}".strip(), fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, dpi=100)
