"""Report charts (issue 22.8): one colour per method across the whole site (the radar and every BadPix-series
chart agree, whatever order a scene ranks the methods in), legends that neither cut long labels nor cover
the curves."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import write_scene, write_submission
from matplotlib.colors import to_hex

from lfbench.cli import main
from lfbench.reports import figures, toolkit_figures
from lfbench.reports.figures import badpix_series_figure
from lfbench.reports.plotting import LEGEND_WIDTH, legend_label, method_colours
from lfbench.reports.toolkit_figures import radar_figure

SIZE = 40
LONG = "planesweep:interval=0.25,interpolation=nearest,subpixel=parabola,d_min=-4,d_max=4"


def test_method_colours_follow_the_order_given_and_stay_distinct():
    labels = [f"m{i}" for i in range(31)]
    colours = method_colours(labels)
    assert list(colours) == labels
    assert colours["m0"] == "#1f77b4" and colours["m1"] == "#ff7f0e"  # matplotlib's default cycle first
    assert len(set(colours[m] for m in labels[:30])) == 30  # 30 methods, 30 colours
    assert colours["m30"] == colours["m0"]  # then the palette starts again
    assert method_colours(["b", "a", "b"]) == {"b": "#1f77b4", "a": "#ff7f0e"}  # by first place, not by name
    assert method_colours(labels[:3]) == {k: colours[k] for k in labels[:3]}  # a method keeps its colour


def test_legend_labels_wrap_to_the_legend_width():
    wrapped = legend_label(LONG)
    assert all(len(line) <= LEGEND_WIDTH for line in wrapped.split("\n")) and len(wrapped.split("\n")) > 1
    assert wrapped.replace("\n", "") == LONG  # every character kept
    assert legend_label("gt") == "gt"
    # breaks only after a comma or a space: never inside a number or a key=value (issue 38)
    assert legend_label("planesweep:d_min=-2.0,d_max=2.0 (4 scenes)") == "planesweep:d_min=-2.0,\nd_max=2.0 (4 scenes)"
    assert legend_label("a" * 40 + ",b") == "a" * 40 + ",\nb"  # a longer token stays whole
    assert legend_label("one two three", width=7) == "one two\nthree"


def _extents(fig):
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    return renderer, fig.bbox


def test_radar_legend_keeps_long_labels_inside_the_figure():
    methods = [f"{LONG}_{i}" for i in range(4)]
    scores = pd.DataFrame(np.arange(20, dtype=float).reshape(5, 4) + 1, columns=methods,
                          index=["badpix_0.07", "badpix_0.03", "badpix_0.01", "mse_x100", "q25_x100"])
    fig = radar_figure(scores)
    renderer, page = _extents(fig)
    texts = fig.axes[0].get_legend().get_texts()
    assert len(texts) == 4
    for text in texts:
        box = text.get_window_extent(renderer)
        assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and box.y1 <= page.y1, box


def test_series_legend_is_beside_the_curves_not_over_them():
    t = np.linspace(0, 0.1, 11)
    series = {f"{LONG}_{i}": (t, 90 - 800 * t + i) for i in range(5)}
    fig = badpix_series_figure(series, "mean over scenes", scenes=dict.fromkeys(series, 2))
    renderer, page = _extents(fig)
    ax = fig.axes[0]
    legend, plot = ax.get_legend().get_window_extent(renderer), ax.get_window_extent(renderer)
    assert legend.x0 >= plot.x1  # right of the axes: no curve under it
    assert legend.x1 <= page.x1 and plot.width > 0.5 * page.width  # inside the figure, the plot still wide
    for text in ax.get_legend().get_texts():
        assert text.get_window_extent(renderer).x1 <= page.x1


@pytest.fixture()
def drawn(tmp_path, monkeypatch):
    """`evaluate --html` of three methods listed worst first (so each scene ranks them in the opposite order
    to the results), recording the colour of every labelled line of every series and radar chart drawn."""
    root = tmp_path / "data"
    rng = np.random.default_rng(3)
    maps = {"worse": {}, "better": {}}
    for i, name in enumerate(("boxes", "cotton")):
        gt = rng.uniform(-1, 1, size=(SIZE, SIZE)).astype(np.float32)
        write_scene(root, name, "training", size=SIZE, seed=i, gt=gt)
        maps["worse"][name] = gt + rng.normal(scale=0.3, size=gt.shape).astype(np.float32)
        maps["better"][name] = gt + rng.normal(scale=0.04, size=gt.shape).astype(np.float32)
    worse, better = (write_submission(tmp_path / k, v) for k, v in maps.items())
    charts: list[tuple[str, dict[str, str]]] = []

    def spy(save):
        def saving(fig, path, *args, **kwargs):
            lines = [line for ax in fig.axes for line in ax.get_lines() if not line.get_label().startswith("_")]
            charts.append((str(path), {line.get_label().replace("\n", ""): to_hex(line.get_color())
                                       for line in lines}))
            return save(fig, path, *args, **kwargs)
        return saving

    monkeypatch.setattr(figures, "save_figure", spy(figures.save_figure))
    monkeypatch.setattr(toolkit_figures, "save_formats", spy(toolkit_figures.save_formats))
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["evaluate", "--data", str(root), "--method", f"published:path={worse}",
                   "--method", f"published:path={better}", "--method", "gt", "--out", str(tmp_path / "run"),
                   "--html", "--figures", "--no-progress"])
    assert rc == 0, err.getvalue()
    return charts


def _method(label: str) -> str:
    """A series label's method: 'gt (2 scenes)' -> 'gt'."""
    return label.rsplit(" (", 1)[0] if label.endswith(("scene)", "scenes)")) else label


def test_each_method_has_one_colour_on_every_chart_of_the_site(drawn):
    expected = method_colours(["published:worse", "published:better", "gt"])  # the results' order
    site = [(path, lines) for path, lines in drawn if "img" in Path(path).parts]  # html/img (built beside, renamed)
    kinds = {Path(p).name for p, _ in site}
    assert {"badpix_series.png", "radar.png"} <= kinds and any(Path(p).parent.name == "boxes" for p, _ in site)
    for path, lines in site:
        if Path(path).name.startswith(("badpix_series", "radar")):
            assert lines, path
            assert {_method(label): colour for label, colour in lines.items()} == {
                _method(label): expected[_method(label)] for label in lines}, path
    # the figures folder of the same run agrees too
    for path, lines in drawn:
        if "figures" in Path(path).parts and Path(path).name == "badpix_series.png":
            assert {_method(k): v for k, v in lines.items()} == {_method(k): expected[_method(k)] for k in lines}
