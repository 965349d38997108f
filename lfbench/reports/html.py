"""A self-contained static HTML report of a run: opens from the file system with no server and no
network (the CSS, the table-sorting script and every image are files of the site; nothing refers to
an http(s) resource).

Layout of the site folder (``OUT/html`` by default)::

    index.html              leaderboard: average ranks, one sortable table per metric (value and rank per
                            scene, mean, average rank; bootstrap intervals when computed; the paper's
                            numbers in labelled columns with --paper), radar chart, BadPix series, and
                            the caller's further tables (an ablation: means over seeds, intervals and
                            verdicts against each baseline)
    scene-<scene>.html      centre view, ground truth, and every method's disparity, BadPix and signed
                            error maps at one colour scale; pairwise comparisons, error heatmaps
    method-<method>.html    one method's numbers and ranks on every scene, its radar chart and maps
    assets/                 site.css, site.js
    img/                    PNG images (maps are drawn from the saved maps at low resolution)

Every number states its resolution (lowres / highres) as the tables do. A reference method (the oracle
``gt``, ``Results.references``) is shown in rows of its own with its numbers and maps, never ranked and never in
the pairwise comparisons, heatmaps over methods, BadPix series or radar chart. The site is written into a
temporary folder and renamed into place when complete.
"""

from __future__ import annotations

import math
import re
import shutil
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from typing import Any
from urllib.parse import quote

import jinja2
import markupsafe
import numpy as np
import pandas as pd

from lfbench.data.dataset import DATASETS, open_datasets
from lfbench.data.disparity import EVALUATION_BORDER_PX
from lfbench.data.scene import HIGHRES, Benchmark
from lfbench.reports import figures as fig
from lfbench.reports import toolkit_figures as tk
from lfbench.reports.leaderboard import all_metric_ranks, metric_table, overall_ranks
from lfbench.reports.maps import MAPS_DIR, SceneMaps, load_scene_maps, map_folders
from lfbench.reports.paper import PAPER_RESOLUTION_COLUMN, average_with_paper, paper_column, per_scene_with_paper
from lfbench.reports.plotting import colormap, method_colours, write_image
from lfbench.reports.tables import average_table, per_scene_table
from lfbench.results import Results
from lfbench.scoring.metrics import describe_metric, metric_order, primary_metric
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.stats import read_ci_csv
from lfbench.utils.atomic import fresh_dir, replace_dir, write_text
from lfbench.utils.errors import DataError
from lfbench.utils.outputs import check_within

__all__ = ["SITE_DIR", "SiteInputs", "SiteSection", "build_site", "build_site_from_dir", "check_site_dir",
           "site_inputs", "site_inputs_from_dir"]

SITE_DIR = "html"
ASSETS = ("site.css", "site.js")
MAX_ALL_PAIRS = 5  # up to this many methods: every pair on a scene page; more: each against the best
FLOATFMT = ".3f"


@dataclass(frozen=True)
class SiteSection:
    """A further table on the index page: ``title``, ``caption`` lines and ``table`` (its index is the
    first column; numbers are shown with three decimals, text as it is), e.g. an ablation's means over
    seeds with their intervals, or its verdicts against each baseline."""

    id: str
    title: str
    table: pd.DataFrame
    caption: Sequence[str] = ()


@dataclass
class SiteInputs:
    """Everything a site is drawn from. ``scenes``: light fields (ground truth, centre view);
    ``maps``: method label -> submission folder of its saved maps; ``scene_maps``: scene name ->
    those maps already loaded (lfbench.reports.maps.load_scene_maps, at the site's border), used instead
    of loading them again; ``ci``: the long bootstrap frame of lfbench.scoring.stats.ci_records
    (ci.csv), or None; ``paper``: PaperTables or None, with ``paper_methods`` (default: the paper's
    own default methods); ``sections``: further tables on the index page; ``curves``: BadPix series
    already computed ((method, scene) -> lfbench.reports.figures.Curve, e.g. by the set's figure writer),
    drawn as they are (the others are computed from the maps by the same function, ``scene_curve``)."""

    results: Results
    scenes: Sequence[Any] = ()
    maps: Mapping[str, Path] = field(default_factory=dict)
    scene_maps: Mapping[str, SceneMaps] = field(default_factory=dict)
    curves: Mapping[tuple[str, str], fig.Curve] = field(default_factory=dict)
    ci: pd.DataFrame | None = None
    paper: Any = None
    paper_methods: Sequence[str] = ()
    title: str = "lfbench results"
    notes: Sequence[str] = ()
    sections: Sequence[SiteSection] = ()


# --------------------------------------------------------------------------- helpers

def _fmt(v: Any, floatfmt: str = FLOATFMT) -> str:
    if v is None or v is pd.NA or (isinstance(v, (float, np.floating)) and math.isnan(v)):
        return "–"
    if isinstance(v, (float, np.floating)):
        return "∞" if math.isinf(v) else format(float(v), floatfmt)
    return str(v)


def _sort_value(v: Any) -> str:
    """The data-v attribute the sorting script reads: a number, or '' (sorted last)."""
    if v is pd.NA:
        return ""
    try:
        f = float(v)
    except (TypeError, ValueError):
        return ""
    return repr(f) if math.isfinite(f) else ""


def page_name(kind: str, label: str) -> str:
    """File name of a scene or method page."""
    return f"{kind}-{fig.safe_name(label)}.html"


def _ci_lookup(ci: pd.DataFrame | None) -> dict[tuple[str, str, str], tuple[float, float]]:
    if ci is None or ci.empty:
        return {}
    out = {}
    for r in ci[["method", "scene", "metric", "low", "high"]].itertuples(index=False):  # not every column a file has
        if np.isfinite(r.low) and np.isfinite(r.high):
            out[(r.method, r.scene, r.metric)] = (float(r.low), float(r.high))
    return out


def _cell(value: Any, rank: Any = None, resolution: str | None = None, ci: tuple[float, float] | None = None,
          best: bool = False) -> dict[str, Any]:
    return {"text": _fmt(value), "v": _sort_value(value), "rank": None if rank is None or not np.isfinite(rank)
            else int(rank), "res": resolution, "ci": None if ci is None else f"[{_fmt(ci[0])}, {_fmt(ci[1])}]",
            "best": best}


# --------------------------------------------------------------------------- tables

def _metric_section(results: Results, metric: str, ci: Mapping, scene_pages: Mapping[str, str],
                    method_pages: Mapping[str, str], ranks: Mapping[str, pd.DataFrame]) -> dict[str, Any]:
    """One metric's table: a row per method (reference rows flagged, shown apart and unranked)."""
    info = describe_metric(metric)
    references = set(results.references)
    table = metric_table(results, metric, ranks=ranks[metric])
    scenes = list(dict.fromkeys(s for s, k in table.columns if s not in ("mean", "average rank")))
    header = []
    for s in scenes:
        res = sorted(set(table[(s, "resolution")].dropna()))
        header.append({"label": s, "res": "/".join(res), "href": scene_pages.get(s)})
    rows = []
    for method in table.index:
        r = table.loc[method]
        cells = []
        for s, h in zip(scenes, header, strict=True):
            res = r[(s, "resolution")]
            rank = r[(s, "rank")]
            cells.append(_cell(r[(s, "value")], rank, res if isinstance(res, str) and res != h["res"] else None,
                               ci.get((method, s, metric)), best=rank == 1))
        mean_ci = ci.get((method, "(mean)", metric))
        rows.append({"method": method, "href": method_pages.get(method), "cells": cells,
                     "mean": _cell(r[("mean", "value")], ci=mean_ci), "mean_res": r[("mean", "resolution")],
                     "avg_rank": _cell(r[("average rank", "value")]), "reference": method in references})
    mean_res = "+".join(sorted({x for row in rows for x in str(row["mean_res"]).split("+") if x and x != "nan"}))
    return {"id": metric, "name": info.name, "unit": info.unit, "description": info.description,
            "direction": info.direction,
            "scenes": header, "rows": rows, "mean_res": mean_res}


def _paper_section(results: Results, metric: str, paper: Any, paper_methods: Sequence[str]) -> dict[str, Any] | None:
    """Rows scene (our scenes the paper reports), columns our methods then the paper's, labelled."""
    table = per_scene_with_paper(per_scene_table(results, [metric]), paper, paper_methods)
    if table.empty:
        return None
    table = table.xs(metric, level="metric")
    ours = [c for c in table.columns if c not in ("resolution", PAPER_RESOLUTION_COLUMN)
            and not str(c).endswith(" (paper)")]
    theirs = [paper_column(m) for m in paper.methods_shown(paper_methods)]
    if table[theirs].isna().all().all():
        return None
    rows = []
    for scene, r in table.iterrows():
        rows.append({"scene": scene, "res": r["resolution"], "paper_res": r[PAPER_RESOLUTION_COLUMN],
                     "ours": [_cell(r[c]) for c in ours], "theirs": [_cell(r[c]) for c in theirs]})
    return {"ours": ours, "theirs": theirs, "rows": rows, "source": str(paper.source)}


def _overview(results: Results, method_pages: Mapping[str, str], paper: Any,
              paper_methods: Sequence[str], metric_ranks: Mapping[str, pd.DataFrame]) -> dict[str, Any]:
    metrics = metric_order(results.metrics)
    ranks = overall_ranks(results, ranks=metric_ranks)
    df = results.to_frame()
    runtime = {}
    for r in results.runs:
        runtime.setdefault(r.method, []).append(r.runtime_s)
    columns = []
    for m in metrics:
        res = "+".join(sorted(set(df.loc[df["metric"] == m, "resolution"])))
        columns.append({"id": m, "name": describe_metric(m).name, "res": res})
    means = average_table(results)
    rows = []
    for method in results.methods:
        cells = [_cell(means.loc[method, m] if m in means.columns else float("nan")) for m in metrics]
        rt = [v for v in runtime.get(method, []) if v is not None and np.isfinite(v)]
        n = df.loc[df["method"] == method, "scene"].nunique()
        rows.append({"method": method, "href": method_pages.get(method), "rank": _cell(ranks.get(method)),
                     "cells": cells, "runtime": _cell(float(np.mean(rt)) if rt else float("nan")), "scenes": n})
    references = [r for r in rows if r["method"] in set(results.references)]  # not ranked: rows of their own
    rows = [r for r in rows if r not in references]
    rows.sort(key=lambda r: (r["rank"]["v"] == "", float(r["rank"]["v"] or 0)))
    for pos, row in enumerate(rows, start=1):
        row["pos"] = pos
    paper_rows = []
    if paper is not None:
        table = average_with_paper(means, paper, results.scenes, paper_methods)
        for label in table.index[len(results.methods):]:
            paper_rows.append({"method": label, "cells": [_cell(table.loc[label].get(m)) for m in metrics],
                               "scenes": int(table.loc[label, "scenes"])})
    return {"columns": columns, "rows": rows, "reference_rows": references, "paper_rows": paper_rows}


def _section_table(section: SiteSection) -> dict[str, Any]:
    """A :class:`SiteSection` as the template shows it: a header and rows of cells (numbers sortable)."""
    table = section.table
    numeric = [pd.api.types.is_numeric_dtype(table[c]) and not pd.api.types.is_bool_dtype(table[c])
               for c in table.columns]
    header = [{"label": str(table.index.name or ""), "kind": "text"}]
    header += [{"label": str(c), "kind": "num" if num else "text"} for c, num in zip(table.columns, numeric,
                                                                                      strict=True)]
    rows = []
    for key, *values in table.itertuples(name=None):  # not iterrows: a row of mixed numbers would turn all float
        cells = [_cell(v) | {"num": True} if num else {"text": _fmt(v), "v": str(v), "num": False}
                 for v, num in zip(values, numeric, strict=True)]
        rows.append({"key": str(key), "cells": cells})
    return {"id": section.id, "title": section.title, "caption": list(section.caption), "header": header,
            "rows": rows}


# --------------------------------------------------------------------------- images

class _Images:
    """Writes the site's PNGs under img/ and hands back their relative paths."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def rgb(self, rel: str, rgb: np.ndarray) -> str:
        write_image(self.root / rel, rgb)
        return rel

    def colorbar(self, cmap: str) -> str:
        rel = f"img/colorbar_{cmap}.png"
        if not (self.root / rel).is_file():
            row = colormap(cmap)(np.linspace(0, 1, 256))[None, :, :3]
            write_image(self.root / rel, np.repeat(row, 12, axis=0))
        return rel


def _legend(images: _Images, disp_range: tuple[float, float]) -> list[dict[str, Any]]:
    return [
        {"label": "disparity (px)", "src": images.colorbar(fig.DISPARITY_CMAP),
         "lo": f"{disp_range[0]:.2f}", "hi": f"{disp_range[1]:.2f}"},
        {"label": "gt − pred (px)", "src": images.colorbar(fig.ERROR_CMAP),
         "lo": f"−{fig.ERROR_LIMIT:g}", "hi": f"+{fig.ERROR_LIMIT:g}"},
        {"label": "|A − gt| − |B − gt| (px): blue A better, red B better", "src": images.colorbar(tk.PAIRWISE_CMAP),
         "lo": f"−{tk.PAIRWISE_LIMIT:g}", "hi": f"+{tk.PAIRWISE_LIMIT:g}"},
        {"label": "median |gt − pred| over methods (px)", "src": images.colorbar(tk.HEATMAP_CMAP),
         "lo": "0", "hi": f"≥ {tk.MEDIAN_ERROR_LIMIT:g}"},
    ]


def _scene_images(sm: SceneMaps, images: _Images, threshold: float, pair_threshold: float,
                  order: Sequence[str], references: Collection[str] = ()) -> dict[str, Any]:
    """Draw one scene's panels; returns what the scene page and method pages show. ``references``
    (oracles) get their maps but take no part in the heatmaps over methods or the pairwise comparisons."""
    d = f"img/{fig.safe_name(sm.name)}"
    out: dict[str, Any] = {"centre": images.rgb(f"{d}/centre.png", sm.centre), "gt": None, "methods": {},
                           "pairs": [], "heatmaps": None, "series": None,
                           "size": f"{sm.centre.shape[1]}×{sm.centre.shape[0]}"}
    if sm.gt is not None:
        out["gt"] = images.rgb(f"{d}/gt.png", fig.disparity_image(sm.gt, *sm.disp_range))
    labels = [m for m in order if m in sm.preds]
    for label in labels:
        panels = fig.method_panels(label, sm.scene, sm.preds[label], gt=sm.gt, mask=sm.mask, background=sm.centre,
                                   disp_range=sm.disp_range, threshold=threshold)
        stem = f"{d}/{fig.safe_name(label)}"
        entry = {"disp": images.rgb(f"{stem}.disp.png", panels.disparity), "badpix": None, "error": None,
                 "badpix_percent": None}
        if panels.badpix is not None:
            entry["badpix_percent"] = panels.badpix_percent if math.isfinite(panels.badpix_percent) else None
            entry["badpix"] = images.rgb(f"{stem}.badpix.png", panels.badpix)
            entry["error"] = images.rgb(f"{stem}.error.png", panels.error)
        out["methods"][label] = entry
    labels = [m for m in labels if m not in references]
    if sm.gt is None or not labels:
        return out
    preds = [sm.preds[m] for m in labels]
    med = tk.median_error_map(sm.gt, preds, sm.mask)
    frac = tk.bad_fraction_map(sm.gt, preds, sm.mask, threshold)
    out["heatmaps"] = {"median": images.rgb(f"{d}/heatmap_median.png", tk.heatmap_image(med, 0, tk.MEDIAN_ERROR_LIMIT)),
                       "fraction": images.rgb(f"{d}/heatmap_badfraction.png", tk.heatmap_image(frac, 0, 100)),
                       "n": len(labels), "threshold": threshold}
    if len(labels) <= MAX_ALL_PAIRS:
        pairs = [(a, b) for i, a in enumerate(labels) for b in labels[i + 1:]]
    else:
        pairs = [(labels[0], b) for b in labels[1:]]
    for k, (a, b) in enumerate(pairs):
        codes = tk.pairwise_classes(sm.gt, sm.preds[a], sm.preds[b], sm.mask, pair_threshold)
        share = tk.pairwise_shares(codes)
        rgb = tk.pairwise_image(sm.gt, sm.preds[a], sm.preds[b], sm.mask, pair_threshold, background=sm.centre)
        out["pairs"].append({"a": a, "b": b, "src": images.rgb(f"{d}/pairwise_{k}.png", rgb),
                             "a_better": _fmt(share["a_better"], ".1f"), "b_better": _fmt(share["b_better"], ".1f"),
                             "tie": _fmt(share["tie"], ".1f")})
    return out


# --------------------------------------------------------------------------- the site

def _environment() -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.PackageLoader("lfbench.reports", "site_assets"),
                             autoescape=jinja2.select_autoescape(["html"]), undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True)
    env.filters["href"] = lambda path: quote(str(path), safe="/=")  # a relative link to a file of the site
    env.filters["breakable"] = breakable
    return env


def breakable(text: Any, after: str = ",:") -> markupsafe.Markup:
    """``text`` escaped for HTML, with a line-break opportunity (``<wbr>``) after each character of ``after``
    not followed by a space (a method spec's commas and colon; a column id's underscores too): it wraps there in
    a narrow column, never inside a number or a key=value."""
    return markupsafe.Markup(re.sub(f"([{re.escape(after)}])(?! )", r"\1<wbr>", str(markupsafe.escape(str(text)))))


def _meta_lines(results: Results) -> list[str]:
    meta = results.meta
    lines = []
    scoring = meta.get("scoring") or {}
    if scoring:
        rule = ("toolkit rule (BadPix counts NaN as good)" if scoring.get("toolkit_nonfinite")
                else "non-finite predictions count as bad pixels")
        highres = ", ".join(scoring.get("highres_scenes", []))  # none: a dataset without high resolution
        lines.append(f"Scoring: {scoring.get('border_px', EVALUATION_BORDER_PX)} px border ignored; {rule}"
                     + (f"; high resolution where available for {highres}." if highres else "."))
    if meta.get("created"):
        lines.append(f"Created {meta['created']} with lfbench {meta.get('lfbench_version', '?')}.")
    return lines


def _dataset_line(results: Results, border: int) -> str:
    """What every page says first of the data: the dataset, its disparity range and the border ignored."""
    name = results.meta.get("dataset")
    lo_hi = results.disparity_range
    if lo_hi is None and name:  # results written before the protocol was recorded: the dataset's own
        found = DATASETS.find(name)
        lo_hi = found.protocol.disparity_range if found is not None and not found.protocol_from_data() else None
    parts = [f"Dataset: {name}" if name else "Dataset: not recorded"]
    if lo_hi is not None:
        parts.append(f"disparity range [{lo_hi[0]:g}, {lo_hi[1]:g}] px per view step")
    parts.append(f"{border} px border ignored")
    return "; ".join(parts) + "."


def check_site_dir(out: str | Path) -> Path:
    """``out`` as the site's folder, refused (DataError) when it exists and is not a folder: check it
    before the work whose report goes there."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise DataError("exists and is not a folder (the HTML report goes there)", out)
    return out


def build_site(inputs: SiteInputs, out: str | Path, *, thresholds: fig.Thresholds | None = None,
               pairwise_threshold: float = tk.PAIRWISE_THRESHOLD, border_px: int | None = None) -> Path:
    """Write the site into folder ``out`` (replacing an earlier site there as a whole); returns the
    path of index.html. ``thresholds``: the BadPix thresholds of the maps, captions and series (default: the
    results' protocol's, :attr:`lfbench.results.Results.protocol_metrics`). Pages and images are named after
    the methods and scenes, whose names the entry point checked (lfbench.results.check_names: a run's before
    its work, a results file's when read)."""
    results = inputs.results
    if not results.records:
        raise DataError("the results hold no records; nothing to report")
    out = check_site_dir(out)
    border = border_px if border_px is not None else ScoringRules.from_meta(results.meta).border_px
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = fresh_dir(out.parent, f".{out.name}.", ".tmp")
    try:
        thresholds = thresholds or fig.Thresholds.of_metrics(results.protocol_metrics)
        _write_site(inputs, tmp, thresholds, pairwise_threshold, border)
        replace_dir(tmp, out)
    except OSError as exc:  # named where the file would have landed, not in the temporary folder
        shutil.rmtree(tmp, ignore_errors=True)
        name = Path(exc.filename) if exc.filename else None
        if name is None or not name.is_relative_to(tmp) or exc.errno is None:
            raise
        raise type(exc)(exc.errno, exc.strerror, str(out / name.relative_to(tmp))) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out / "index.html"


def _write_site(inputs: SiteInputs, root: Path, thresholds: fig.Thresholds, pair_threshold: float,
                border: int) -> None:
    results = inputs.results
    threshold, marked = thresholds.primary, thresholds.marked
    env = _environment()
    assets = files("lfbench.reports").joinpath("site_assets")
    for name in ASSETS:
        write_text(root / "assets" / name, assets.joinpath(name).read_text(encoding="utf-8"))
    images = _Images(root)
    methods = results.methods
    scenes_by_name = {s.name: s for s in inputs.scenes}
    scene_names = [s for s in results.scenes]
    scene_pages = {s: page_name("scene", s) for s in scene_names}
    method_pages = {m: page_name("method", m) for m in methods}
    ci = _ci_lookup(inputs.ci)
    metrics = metric_order(results.metrics)
    references = set(results.references)  # oracles: reference rows, never ranked or compared
    ranks = all_metric_ranks(results)  # every table below ranks from these
    orders = {s: _scene_order(results, s, ranks) for s in scene_names}
    sections = [_metric_section(results, m, ci, scene_pages, method_pages, ranks) for m in metrics]
    paper_sections = {}
    if inputs.paper is not None:
        for m in metrics:
            sec = _paper_section(results, m, inputs.paper, inputs.paper_methods)
            if sec is not None:
                paper_sections[m] = sec
    overview = _overview(results, method_pages, inputs.paper, inputs.paper_methods, ranks)

    # maps, drawn scene by scene (one scene's arrays in memory at a time unless the caller loaded them all)
    drawn: dict[str, dict[str, Any]] = {}
    curves: list[fig.Curve] = []
    colours = method_colours(methods)  # one colour per method on every chart of the site
    rules = _rules(results)
    for name in scene_names:
        scene = scenes_by_name.get(name)
        if scene is None:
            continue
        sm = inputs.scene_maps.get(name)
        if sm is None:
            sm = load_scene_maps(scene, inputs.maps, border)
        order = [m for m in orders[name] if m in sm.preds]
        drawn[name] = _scene_images(sm, images, threshold, pair_threshold, order, references)
        drawn[name]["legend"] = _legend(images, sm.disp_range)
        for label in (m for m in order if m not in references):  # an oracle's BadPix(t) is 0: no line
            if hasattr(scene, "has_gt"):
                c = inputs.curves.get((label, name)) or fig.scene_curve(label, scene, sm.preds[label], rules,
                                                                          thresholds.curve)
                if c is not None:
                    curves.append(c)
        if curves and any(c.scene == name for c in curves):
            series = {c.method: (c.thresholds, c.values) for c in curves if c.scene == name}
            res = "/".join(sorted({c.resolution for c in curves if c.scene == name}))
            path = root / "img" / fig.safe_name(name) / "badpix_series.png"
            fig.plot_badpix_series(series, path, f"BadPix series, {name} ({res})", colours=colours, marked=marked)
            drawn[name]["series"] = f"img/{fig.safe_name(name)}/badpix_series.png"
        del sm
    figures: dict[str, str | None] = {"series": None, "radar": None, "radar_metrics": None}
    if curves:
        fig.plot_mean_series(fig.average_curves(curves), root / "img" / "badpix_series.png",
                             "BadPix series, mean over scenes", colours=colours, marked=marked)
        figures["series"] = "img/badpix_series.png"
    else:
        averaged = {m: c for m, c in fig.curves_from_records(results).items() if m not in references}
        if averaged:
            fig.plot_mean_series(averaged, root / "img" / "badpix_series.png",
                                 "BadPix at the thresholds in the results, mean over scenes", markers=True,
                                 colours=colours, marked=marked)
            figures["series"] = "img/badpix_series.png"
    radar = tk.radar_scores(results, methods=results.competitors)
    radar_ok = len(radar.index) >= 3
    if radar_ok:
        tk.plot_radar(radar, root / "img" / "radar.png", colours=colours)
        figures["radar"] = "img/radar.png"
        figures["radar_metrics"] = ", ".join(tk.radar_axis_name(m) for m in radar.index)

    common = {"title": inputs.title, "methods": [{"label": m, "href": method_pages[m]} for m in methods],
              "scenes": [{"label": s, "href": scene_pages[s]} for s in scene_names],
              "meta": _meta_lines(results) + list(inputs.notes), "dataset": _dataset_line(results, border),
              "marked": ", ".join(f"{t:g}" for t in marked)}
    index = env.get_template("index.html").render(
        **common, page="index", overview=overview, sections=sections, paper=paper_sections,
        paper_source=str(inputs.paper.source) if inputs.paper is not None else None, figures=figures,
        scene_cards=[{"label": s, "href": scene_pages[s], "thumb": drawn.get(s, {}).get("centre"),
                      "res": "/".join(sorted({r.resolution for r in results.records if r.scene == s}))}
                     for s in scene_names],
        has_ci=bool(ci), threshold=threshold, tables=[_section_table(t) for t in inputs.sections],
        highres_scenes=sorted({r.scene for r in results.records if r.resolution == HIGHRES}))
    write_text(root / "index.html", index)
    for s in scene_names:
        write_text(root / scene_pages[s], env.get_template("scene.html").render(
            **common, page="scene", scene=s, maps=drawn.get(s),
            scene_table=_scene_table(results, s, method_pages, ranks, orders[s]),
            threshold=threshold, pair_threshold=pair_threshold, border=border))
    for m in methods:
        radar_src = None
        if radar_ok and m in radar.columns:
            rel = f"img/radar_{fig.safe_name(m)}.png"
            tk.plot_radar(radar, root / rel, highlight=m, title=f"{m} against the other methods (median over scenes)",
                          colours=colours)
            radar_src = rel
        write_text(root / method_pages[m], env.get_template("method.html").render(
            **common, page="method", method=m, method_table=_method_table(results, m, scene_pages, ci, ranks),
            radar=radar_src, maps=[{"scene": s, "href": scene_pages[s], "legend": drawn[s]["legend"],
                                    **drawn[s]["methods"][m]}
                                   for s in scene_names if s in drawn and m in drawn[s]["methods"]],
            threshold=threshold))


def _rules(results: Results) -> ScoringRules:
    """The results' scoring rules; high resolution allowed when any number was scored there (or none is)."""
    highres_used = any(r.resolution == "highres" for r in results.records)
    return ScoringRules.from_meta(results.meta, allow_highres=highres_used or not results.records)


def _scene_order(results: Results, scene: str, metric_ranks: Mapping[str, pd.DataFrame]) -> list[str]:
    """Methods on a scene, best first in the protocol's primary metric (lfbench.scoring.metrics.primary_metric:
    BadPix(0.07) on HCI) where the results hold it, else in their first metric."""
    held = [m for m in results.protocol_metrics if m in results.metrics]
    metric = primary_metric(held) or metric_order(results.metrics)[0]
    ranks = metric_ranks[metric]
    ranks = ranks[ranks["scene"] == scene]
    order = dict(zip(ranks["method"], ranks["rank"].fillna(np.inf), strict=True))
    return sorted(results.methods, key=lambda m: (order.get(m, np.inf), results.methods.index(m)))


def _scene_table(results: Results, scene: str, method_pages: Mapping[str, str], ranks: Mapping[str, pd.DataFrame],
                 order: Sequence[str]) -> dict[str, Any]:
    """Rows method (in the scene's ``order``), columns metric: the value with its rank on this scene; the
    reference methods (oracles) in rows of their own, unranked."""
    references = set(results.references)
    metrics = [m for m in metric_order(results.metrics)]
    cols, by = [], {}
    for m in metrics:
        long = ranks[m]
        long = long[long["scene"] == scene]
        if long.empty:
            continue
        cols.append({"id": m, "name": describe_metric(m).name, "res": "/".join(sorted(set(long["resolution"])))})
        for r in long.itertuples(index=False):
            by[(r.method, m)] = (r.value, r.rank)
    rows = []
    for method in order:
        if not any((method, c["id"]) in by for c in cols):
            continue
        cells = [_cell(*by.get((method, c["id"]), (float("nan"), None)), best=by.get((method, c["id"]),
                                                                                     (0, 0))[1] == 1) for c in cols]
        rows.append({"method": method, "href": method_pages.get(method), "cells": cells,
                     "reference": method in references})
    return {"columns": cols, "rows": [r for r in rows if not r["reference"]],
            "reference_rows": [r for r in rows if r["reference"]]}


def _method_table(results: Results, method: str, scene_pages: Mapping[str, str], ci: Mapping,
                  ranks: Mapping[str, pd.DataFrame]) -> dict[str, Any]:
    """Rows scene, columns metric: the method's value and rank among the ranked methods on that scene
    (a reference method, an oracle, has values and no ranks)."""
    metrics = metric_order(results.metrics)
    by, res = {}, {}
    for m in metrics:
        long = ranks[m]
        n = long.groupby("scene")["rank"].count()
        for r in long[long["method"] == method].itertuples(index=False):
            by[(r.scene, m)] = (r.value, r.rank, int(n.get(r.scene, 0)))
            res[(r.scene, m)] = r.resolution
    cols = [{"id": m, "name": describe_metric(m).name} for m in metrics if any(k[1] == m for k in by)]
    rows = []
    for s in results.scenes:
        if not any((s, c["id"]) in by for c in cols):
            continue
        cells = []
        for c in cols:
            v, rank, _ = by.get((s, c["id"]), (float("nan"), None, 0))
            cells.append(_cell(v, rank, res.get((s, c["id"])), ci.get((method, s, c["id"])), best=rank == 1))
        rows.append({"scene": s, "href": scene_pages.get(s), "cells": cells})
    return {"columns": cols, "rows": rows, "n_methods": len(results.competitors),
            "reference": method in results.references}


# --------------------------------------------------------------------------- from a results folder

def site_inputs_from_dir(results_path: str | Path, *, data_root: str | Path | None = None,
                         maps: str | Path | None = None, scenes: Sequence[Any] | None = None, paper: Any = None,
                         paper_methods: Sequence[str] = (), title: str | None = None) -> SiteInputs:
    """What a results folder holds for a site: results.json, ci.csv (when ``--ci`` ran), the saved maps
    (``maps`` or RESULTS_DIR/maps when present) and the scenes of ``data_root`` (default: the data
    root the results record, when it exists), or ``scenes`` (those the results were scored on)."""
    results_path = Path(results_path)
    folder = results_path if results_path.is_dir() else results_path.parent
    return site_inputs(Results.read(results_path), folder, data_root=data_root, maps=maps, scenes=scenes, paper=paper,
                       paper_methods=paper_methods, title=title)


def site_inputs(results: Results, folder: Path, *, data_root: str | Path | Sequence[str | Path] | None = None,
                maps: str | Path | Mapping[str, Path] | None = None, scenes: Sequence[Any] | None = None,
                scene_maps: Mapping[str, SceneMaps] | None = None,
                curves: Mapping[tuple[str, str], fig.Curve] | None = None, paper: Any = None,
                paper_methods: Sequence[str] = (), title: str | None = None) -> SiteInputs:
    """:func:`site_inputs_from_dir` for ``results`` already read from the results folder ``folder``.
    ``maps``: a folder of submission folders, or method label -> submission folder (those that hold
    maps are used); ``data_root``: one data root or several (default: those the results record); ``scenes``:
    the results' scenes of the data root when already discovered (then
    ``data_root`` is not searched again); ``scene_maps``: their saved maps when already loaded; ``curves``:
    BadPix series already computed (SiteInputs)."""
    ci = None
    if (folder / "ci.csv").is_symlink():
        check_within(folder / "ci.csv", folder, "the results folder")
    if (folder / "ci.csv").is_file():
        ci = read_ci_csv(folder / "ci.csv")
    if isinstance(maps, Mapping):
        folders = {label: Path(f) for label, f in maps.items() if (Path(f) / "disp_maps").is_dir()}
    else:
        maps_dir = Path(maps) if maps is not None else folder / MAPS_DIR
        folders = (map_folders(maps_dir, results.methods, within=None if maps is not None else folder)
                   if (maps is not None or maps_dir.is_dir()) else {})
    given = Benchmark.root_list(data_root)
    roots = given or results.data_roots
    notes = []
    if scenes is not None:
        scenes = list(scenes)
    elif roots and (given or all(r.is_dir() for r in roots)):
        scenes = open_datasets(roots, results.meta.get("dataset"))[2].named(results.scenes)
    elif roots:
        missing = ", ".join(str(r) for r in roots if not r.is_dir())
        notes.append(f"The data root {missing} recorded in the results is not here: no maps are shown "
                     "(give --data ROOT).")
    scenes = scenes or []
    if not folders:
        shown = "the scenes and the numbers" if scenes else "the numbers only"
        notes.append(f"No saved maps: scene pages show {shown}, no method's maps (evaluate with --save-maps or "
                     "--html).")
    return SiteInputs(results=results, scenes=scenes, maps=folders, scene_maps=dict(scene_maps or {}),
                      curves=dict(curves or {}), ci=ci,
                      paper=paper, paper_methods=paper_methods, title=title or _default_title(results), notes=notes)


def _default_title(results: Results) -> str:
    if results.meta.get("demo"):
        return "lfbench demo"
    if (results.meta.get("ablation") or {}).get("title"):
        return str(results.meta["ablation"]["title"])
    return "lfbench results"


def build_site_from_dir(results_path: str | Path, out: str | Path | None = None, **kwargs: Any) -> Path:
    """:func:`site_inputs_from_dir` then :func:`build_site` into ``out`` (default RESULTS_DIR/html)."""
    results_path = Path(results_path)
    folder = results_path if results_path.is_dir() else results_path.parent
    inputs = site_inputs_from_dir(results_path, **kwargs)
    return build_site(inputs, Path(out) if out is not None else folder / SITE_DIR)
