"""Table IV without training: a training-free method (the plane sweep) at several disparity intervals x
interpolations, from an ablation run of ``[[methods]]`` whose specs carry ``interval`` and ``interpolation``.

``python -m lfbench.reports.sweep_table RUN_DIR OUT_DIR`` reads RUN_DIR/methods/*/{method.json, results.json}
(each method's own results, so a run still in progress gives the rows it has) and writes into OUT_DIR:

- ``interval_sweep.{md,tex,csv}``: one row per (scene group, interpolation, sub-pixel fit, interval) with
  every general metric the methods were scored in (in the one display order, headed by each Metric's label:
  BadPix 0.07 / 0.03 / 0.01 (%), MSE x100, Q25) and the mean time per scene (s); scene groups: each real scene by
  name (scored at low resolution, 512 x 512, as the benchmark's lowres numbers) and ``synthetic (mean of n)``;
- ``figures/interval_sweep.png``: the first of them (BadPix 0.07) against the interval, one line per
  interpolation and fit, one panel per scene group.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from lfbench.data.scene import LOWRES
from lfbench.method.registry import parse_spec
from lfbench.reports.plotting import INTERPOLATION_COLOURS, pyplot, save_figure
from lfbench.reports.tables import write_table
from lfbench.results import Results
from lfbench.scoring.metrics import METRICS, get_metric, metric_order
from lfbench.utils.errors import DataError, LFBenchError
from lfbench.utils.figure_text import plain_text
from lfbench.utils.jsonfile import read_json

__all__ = ["SYNTH_PREFIX", "collect", "main", "scene_group", "sweep_figure", "sweep_table"]

SYNTH_PREFIX = "synth_"


def collect(run_dir: str | Path) -> pd.DataFrame:
    """Long frame of every finished method of an ablation run: label, interval, interpolation, subpixel,
    scene, metric, value (low resolution only; the general metrics: lfbench.scoring.metrics), runtime_s
    (that scene's)."""
    rows = []
    for folder in sorted(Path(run_dir, "methods").glob("*")):
        meta_path, res_path = folder / "method.json", folder / "results.json"
        if not (meta_path.is_file() and res_path.is_file()):
            continue  # not finished yet
        meta = read_json(meta_path, "method marker")
        res = Results.read(res_path)
        name, params = parse_spec(meta["spec"])
        runtimes = {r.scene: r.runtime_s for r in res.runs}
        for r in res.records:
            if r.resolution != LOWRES or _category(r.metric) != "general":
                continue
            rows.append({"label": meta["label"], "method": name, "interval": float(params.get("interval", 0.25)),
                         "interpolation": str(params.get("interpolation", "bilinear")),
                         "subpixel": str(params.get("subpixel", "equiangular")), "scene": r.scene,
                         "metric": r.metric, "value": r.value, "runtime_s": runtimes.get(r.scene)})
    return pd.DataFrame(rows)


def _category(metric: str) -> str | None:
    found = METRICS.find(metric)
    return found.category if found is not None else None


def table_metrics(frame: pd.DataFrame) -> list[str]:
    """The metric ids the sweep shows: those of ``frame`` in the one display order (metric_order)."""
    return metric_order(dict.fromkeys(frame["metric"])) if len(frame) else []


def scene_group(scene: str, synth_count: int) -> str:
    """The scene group a scene's scores are averaged in: ``synthetic (mean of n)`` for the generated scenes,
    else the scene itself (each real scene is its own group)."""
    return f"synthetic (mean of {synth_count})" if scene.startswith(SYNTH_PREFIX) else scene


def sweep_table(frame: pd.DataFrame, metrics: Sequence[str] | None = None) -> pd.DataFrame:
    """One row per (scenes, interpolation, sub-pixel fit, interval): ``metrics`` (default :func:`table_metrics`;
    mean over the group's scenes, headed by their Metric label) and the mean time per scene. Real scenes first
    (by name), then the synthetic mean."""
    if frame.empty:
        return pd.DataFrame()
    metrics = table_metrics(frame) if metrics is None else list(metrics)
    synth = frame.loc[frame["scene"].str.startswith(SYNTH_PREFIX), "scene"].nunique()
    f = frame.assign(scenes=[scene_group(s, synth) for s in frame["scene"]])
    keys = ["scenes", "interpolation", "subpixel", "interval"]
    values = f.pivot_table(index=keys, columns="metric", values="value", aggfunc="mean")
    times = f.drop_duplicates(["label", "scene"]).groupby(keys)["runtime_s"].mean()
    out = values.reindex(columns=metrics).rename(columns={m: get_metric(m).label for m in metrics})
    out["time per scene (s)"] = times
    out = out.reset_index()
    real_first = {g: (g.startswith("synthetic"), g) for g in out["scenes"].unique()}
    out["_g"] = out["scenes"].map(real_first)
    out["_fit"] = out["subpixel"] != "equiangular"
    out = out.sort_values(["_g", "_fit", "interpolation", "interval"], ascending=[True, True, True, False])
    out = out.drop(columns=["_g", "_fit"]).rename(columns={"subpixel": "sub-pixel fit", "interval": "interval (px)"})
    out["interval (px)"] = [f"{v:g}" for v in out["interval (px)"]]  # a label, not a measured number
    return out.set_index("scenes")


@plain_text
def sweep_figure(table: pd.DataFrame, path: Path, metric: str = "badpix_0.07") -> Path:
    """``metric`` (a column of :func:`sweep_table`, by its id) against the interval (log axis, coarse to fine),
    a line per interpolation and fit, a panel per scene group."""
    plt = pyplot()
    label = get_metric(metric).label
    groups = list(dict.fromkeys(table.index))
    fig, axes = plt.subplots(1, len(groups), figsize=(4.2 * len(groups), 3.8), squeeze=False)
    for ax, group in zip(axes[0], groups, strict=True):
        sel = table.loc[[group]]
        for (interp, fit), rows in sel.groupby(["interpolation", "sub-pixel fit"], sort=False):
            xs = rows["interval (px)"].astype(float)
            colour = INTERPOLATION_COLOURS.get(interp, "tab:gray")
            ax.plot(xs, rows[label], marker="o", color=colour,
                    linestyle="-" if fit == "equiangular" else "--",
                    label=f"{interp}" + ("" if fit == "equiangular" else f", fit {fit}"))
        ax.set_xscale("log")
        ax.invert_xaxis()
        ticks = sorted(set(sel["interval (px)"].astype(float)), reverse=True)
        ax.set_xticks(ticks)
        ax.set_xticklabels([f"{t:g}" for t in ticks])
        ax.minorticks_off()
        ax.set_xlabel("disparity interval (px)")
        ax.set_ylabel(label)
        ax.set_title(group, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"Plane sweep (no training): {label} vs disparity interval", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m lfbench.reports.sweep_table", description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir", type=Path, help="an lfbench ablate output folder (its methods/ subfolder is read)")
    p.add_argument("out_dir", type=Path, help="where the table and the figure go")
    p.add_argument("--caption", action="append", default=[], help="a caption line (repeatable)")
    args = p.parse_args(argv)
    try:
        if not (args.run_dir / "methods").is_dir():
            raise DataError("not an ablation output folder (no methods/ inside)", args.run_dir)
        frame = collect(args.run_dir)
        if frame.empty:
            raise DataError("no finished method results under methods/", args.run_dir)
        table = sweep_table(frame)
        written = write_table(table, args.out_dir, "interval_sweep", args.caption)
        written.append(sweep_figure(table, args.out_dir / "figures" / "interval_sweep.png", table_metrics(frame)[0]))
    except LFBenchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    done = frame["label"].nunique()
    print(f"{done} method(s), {len(table)} rows; wrote {', '.join(str(w) for w in written)}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
