"""Names and text from users where they go (issue 20, classes 2 and 4).

LaTeX: every string that reaches a .tex file (titles, captions, method labels, scene names, notes, column
headers) is escaped by lfbench.reports.latex, so a title ``"tiny\\n\\\\input{/etc/passwd}"`` cannot end
its ``%`` comment and start a line with a command. Each .tex is read back by :func:`read_tex`, a strict
reader written here (independent of lfbench) that knows only the escapes and the table's structure lines
and fails on anything else; the text it reads must be the intended text.

Figures: labels holding ``$...$`` (``$\\x$`` is not valid mathtext) are drawn as plain text by every
command and function that draws figures.
"""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import numpy as np
import pytest
from helpers import run_cli, write_scene, write_submission
from hypothesis import given
from hypothesis import strategies as st

from lfbench.reports.latex import escape

# --------------------------------------------------------------------------- a strict reader of the .tex lfbench writes

_ESCAPES = {r"{\textbackslash}": "\\", r"\{": "{", r"\}": "}", r"\$": "$", r"\&": "&", r"\%": "%", r"\#": "#",
            r"\_": "_", r"{\textasciicircum}": "^", r"{\textasciitilde}": "~", r"{\textless}": "<",
            r"{\textgreater}": ">", r"{\textbar}": "|", "{[}": "[", "{]}": "]"}
_STRUCTURE = re.compile(r"\\begin\{tabular\}\{l+\}|\\toprule|\\midrule|\\bottomrule|\\end\{tabular\}")
MATHTEXT_BREAKER = "$\\x$"  # matplotlib's mathtext: "Unknown symbol: \x"
INJECTION = "tiny\n\\input{/etc/passwd}"


def tex_text(tex: str) -> str:
    """The characters an escaped LaTeX fragment typesets; AssertionError on a command or a special
    character that is not one of the escapes (nothing else may reach a .tex file)."""
    out, i = [], 0
    while i < len(tex):
        for token, char in _ESCAPES.items():
            if tex.startswith(token, i):
                out.append(char)
                i += len(token)
                break
        else:
            assert tex[i] not in "\\{}$&%#_^~[]", f"unescaped {tex[i]!r} at {i} in {tex!r}"
            assert unicodedata.category(tex[i]) not in ("Cc", "Zl", "Zp"), f"control character in {tex!r}"
            out.append(tex[i])
            i += 1
    return "".join(out)


def read_tex(path: Path) -> tuple[list[str], list[list[str]]]:
    """(caption lines, table rows with the header first) of a .tex table written by lfbench, as text."""
    text = path.read_text(encoding="utf-8")
    assert "\\input" not in text and "\\include" not in text
    captions: list[str] = []
    rows: list[list[str]] = []
    lines = text.split("\n")
    assert lines[-1] == "", "a .tex file ends with a newline"
    for line in lines[:-1]:
        if line.startswith("% "):
            assert not rows, "captions come first"
            captions.append(tex_text(line[2:]))
        elif _STRUCTURE.fullmatch(line):
            continue
        else:
            assert line.startswith(" ") and line.endswith(" \\\\"), f"not a table row: {line!r}"
            assert not re.match(r"\s*\\[A-Za-z@]", line), f"a row starts with a command: {line!r}"
            rows.append([tex_text(cell.strip()) for cell in re.split(r"(?<!\\)&", line[1:-3])])
    return captions, rows


def one_line(text: str) -> str:
    """``text`` as lfbench writes it into a .tex file: line breaks and control characters as spaces."""
    return "".join(" " if unicodedata.category(c) in ("Cc", "Zl", "Zp") else c for c in text)


def tex_files(folder: Path) -> list[Path]:
    files = sorted(folder.rglob("*.tex"))
    assert files, f"no .tex under {folder}"
    return files


# --------------------------------------------------------------------------- the one escaping function

@given(st.text())
def test_escape_typesets_any_text_as_itself_on_one_line(text):
    tex = escape(text)
    assert tex_text(tex) == one_line(text)
    assert len(tex.splitlines()) <= 1
    assert not re.match(r"\s*\\[A-Za-z@]", tex)  # not even a command at its start


def test_escape_by_hand():
    assert escape(INJECTION) == r"tiny {\textbackslash}input\{/etc/passwd\}"
    assert escape("50% of a_b & c#1 ~ ^ $x$") == r"50\% of a\_b \& c\#1 {\textasciitilde} {\textasciicircum} \$x\$"
    assert escape("[3pt] <a|b>\r\n\f\u2028") == r"{[}3pt{]} {\textless}a{\textbar}b{\textgreater}    "


def test_write_table_escapes_captions_headers_index_and_cells(tmp_path):
    import pandas as pd

    from lfbench.reports.tables import write_table

    hostile = "m<1>\\input{x}\n% [2pt] & $a^b$ #_~|"
    table = pd.DataFrame({hostile: [1.5, float("nan")], "badpix_0.07": ["note\n\\end{tabular}", "x"]},
                         index=pd.Index([hostile, "s"], name="scene\r\\x"))
    path = next(p for p in write_table(table, tmp_path, "t", [INJECTION, "note: " + hostile]) if p.suffix == ".tex")
    captions, rows = read_tex(path)
    assert captions == [one_line(INJECTION), one_line("note: " + hostile)]
    assert rows == [[one_line("scene\r\\x"), one_line(hostile), "BadPix(0.07)"],
                    [one_line(hostile), "1.500", "note \\end{tabular}"], ["s", "-", "x"]]


def test_markdown_tables_keep_a_hostile_label_in_its_cell(tmp_path):
    """A "|" or a line break in a label, a scene name or a cell cannot add a column or end a row of a
    Markdown table; the cell reads back as the text on one line."""
    import pandas as pd

    from lfbench.reports.tables import write_table

    hostile = "a|b\n| c |\r\nd"
    table = pd.DataFrame({hostile: [1.5, 2.0], "badpix_0.07": ["x|y", "z"]},
                         index=pd.Index([hostile, "s"], name="scene|name"))
    path = next(p for p in write_table(table, tmp_path, "t") if p.suffix == ".md")
    rows = [line for line in path.read_text(encoding="utf-8").splitlines() if line.startswith("|")]
    cells = [[c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", row)[1:-1]] for row in rows]
    assert len(rows) == 4 and {len(r) for r in cells} == {3}
    assert cells[0] == ["scene|name", "a|b | c | d", "BadPix(0.07)"]
    assert cells[2] == ["a|b | c | d", "1.500", "x|y"] and cells[3] == ["s", "2.000", "z"]


def test_bench_table_keeps_a_multi_line_error_in_its_cell():
    """A worker's error (line breaks, a "|") stays in the error cell of its row of the bench table."""
    from lfbench.runs.bench import table

    text = table([{"bench": "peak", "precision": "fp32", "seconds": 1.5, "error": "boom\nline | two"}])
    rows = [line for line in text.splitlines() if line.startswith("|")]
    assert len(rows) == 3 and rows[2].rstrip().endswith("boom line \\| two |")


# --------------------------------------------------------------------------- every path into a .tex file, end to end

SIZE = 40


@pytest.fixture(scope="module")
def hostile_run(tmp_path_factory) -> dict[str, Path | str]:
    """``evaluate --ci --figures --html`` on a scene named with an injection and a mathtext breaker, and a
    published submission in a folder named ``sub$\\x$``."""
    tmp = tmp_path_factory.mktemp("hostile")
    scene = "s" + MATHTEXT_BREAKER + "\n\\input{passwd}%"  # a folder name: no slash
    write_scene(tmp / "data", "renamed", "training", size=SIZE).rename(tmp / "data" / "training" / scene)
    write_scene(tmp / "data", "plain", "training", size=SIZE, seed=1)
    sub = write_submission(tmp / ("sub" + MATHTEXT_BREAKER), {scene: np.full((SIZE, SIZE), 1.05, np.float32),
                                                              "plain": np.full((SIZE, SIZE), 0.9, np.float32)})
    return {"tmp": tmp, "data": tmp / "data", "scene": scene, "sub": sub, "label": "published:" + sub.name}


@pytest.fixture(scope="module")
def evaluated(hostile_run) -> Path:
    from lfbench.cli import main

    out = hostile_run["tmp"] / "out"
    assert main([str(a) for a in ("evaluate", "--data", hostile_run["data"], "--method",
                                  f"published:path={hostile_run['sub']}", "--method", "constant", "--out", out,
                                  "--no-progress", "--ci", "--ci-resamples", "20", "--figures", "--html")]) == 0
    return out


def test_evaluate_tables_hold_the_scene_name_and_label_as_text(hostile_run, evaluated):
    scene, label = one_line(hostile_run["scene"]), hostile_run["label"]
    files = tex_files(evaluated)
    assert {p.name for p in files} == {"table_per_scene.tex", "table_average.tex", "table_ci_per_scene.tex"}
    for path in files:
        read_tex(path)
    _, rows = read_tex(evaluated / "table_per_scene.tex")
    assert label in rows[0] and {r[0] for r in rows[1:]} == {scene, "plain"}
    _, rows = read_tex(evaluated / "table_average.tex")
    assert {r[0] for r in rows[1:]} == {label, "constant"}
    _, rows = read_tex(evaluated / "table_ci_per_scene.tex")
    assert any(scene in r for r in rows[1:])


def test_evaluate_draws_labels_with_dollars_as_plain_text(hostile_run, evaluated):
    """A label holding $\\x$ (a published folder, a scene): every figure and the HTML report are written."""
    figures = evaluated / "figures"
    overviews = sorted(p.name for p in figures.glob("overview_*.png"))
    assert len(overviews) == 2 and (figures / "badpix_series.png").is_file()
    assert all((figures / name).stat().st_size > 1000 for name in overviews)
    assert (evaluated / "html" / "index.html").is_file()
    assert len(list((evaluated / "html").glob("method-*.html"))) == 2


def test_report_from_hostile_results_escapes_and_draws(hostile_run, evaluated, capsys):
    """``report`` reads method and scene names back from results.json: its tables and the toolkit's
    figures (radar, heatmaps, pairwise maps) take them as text."""
    out = hostile_run["tmp"] / "report"
    rc, _, err = run_cli(capsys, "report", evaluated, "--out", out, "--maps", evaluated / "maps", "--html")
    assert rc == 0, err
    for path in tex_files(out):
        _, rows = read_tex(path)
        assert rows
    toolkit = out / "figures" / "toolkit"
    assert (toolkit / "radar.png").is_file() and (toolkit / "error_heatmaps.png").is_file()
    assert len(list(toolkit.glob("pairwise_*.png"))) == 1


def test_ablation_title_and_method_label_cannot_inject(tmp_path, capsys):
    """The issue's example: the spec's title in every caption, a [[methods]] label in every row."""
    label = "m" + MATHTEXT_BREAKER + " & 50%\n\\input{x}"
    spec = tmp_path / "spec.toml"
    spec.write_text(f'title = "{_toml(INJECTION)}"\n[evaluation]\nsynthetic = {{ seed = 5, size = 48, scenes = 1 }}\n'
                    f'[[methods]]\nlabel = "{_toml(label)}"\nspec = "constant"\n', encoding="utf-8")
    rc, _, err = run_cli(capsys, "-q", "ablate", spec, "--out", tmp_path / "ab")
    assert rc == 0, err
    files = tex_files(tmp_path / "ab")
    assert {p.name for p in files} >= {"table_per_scene.tex", "table_average.tex"}
    for path in files:
        captions, rows = read_tex(path)
        assert captions[0].startswith(one_line(INJECTION))
        assert one_line(label) in [r[0] for r in rows] + rows[0]
    maps = list((tmp_path / "ab" / "figures" / "error_maps").glob("overview_*.png"))
    assert len(maps) == 1  # the label's error maps, drawn as plain text
    # a note given as a caption line of the sweep table (python -m lfbench.reports.sweep_table)
    from lfbench.reports.sweep_table import main as sweep_main

    note = "note " + MATHTEXT_BREAKER + "\n\\input{x}\r\\write18{rm}"
    assert sweep_main([str(tmp_path / "ab"), str(tmp_path / "sweep"), "--caption", note]) == 0
    captions, rows = read_tex(tmp_path / "sweep" / "interval_sweep.tex")
    assert captions == [one_line(note)] and len(rows) == 2
    assert (tmp_path / "sweep" / "figures" / "interval_sweep.png").is_file()


def _toml(text: str) -> str:
    return text.replace("\\", "\\\\").replace("\n", "\\n").replace('"', '\\"')


# --------------------------------------------------------------------------- every other function that draws

def test_training_and_ablation_figures_draw_dollar_labels(tmp_path):
    import pandas as pd

    from lfbench.ablation.plots import Points, accuracy_vs_time, metric_curve
    from lfbench.reports.sweep_table import sweep_figure
    from lfbench.reports.uncertainty import plot_sparsification
    from lfbench.scoring.metrics import get_metric
    from lfbench.scoring.uncertainty import Sparsification
    from lfbench.training.curves import plot_learning_curve

    entries = [{"event": "train", "stage": 1, "stage_name": MATHTEXT_BREAKER, "global_step": s, "loss": 1.0 / (s + 1)}
               for s in range(5)]
    entries.append({"event": "validation", "global_step": 4, "badpix": 50.0, "mse_x100": 3.0})
    written = [plot_learning_curve(entries, tmp_path / "curve.png", title=MATHTEXT_BREAKER)]
    f = np.linspace(0, 0.9, 10)
    sp = Sparsification(f, 1 - f, 0.5 * (1 - f), np.ones_like(f), "abs", "px", 100, False)
    written.append(plot_sparsification({MATHTEXT_BREAKER: sp}, tmp_path / "sparse.png", title=MATHTEXT_BREAKER))
    frame = pd.DataFrame({"beta": [0.1, 1.0], "badpix_0.07": [10.0, 20.0], "test_s": [1.0, 2.0],
                          "interval": [0.5, 1.0], "interpolation": [MATHTEXT_BREAKER, "bilinear"]},
                         index=["beta=0.1", "beta=1"])
    records = pd.DataFrame({"method": ["beta=0.1", "beta=1"], "scene": [MATHTEXT_BREAKER] * 2,
                            "metric": ["badpix_0.07"] * 2, "value": [10.0, 20.0]})
    written.append(metric_curve(frame["badpix_0.07"], frame["beta"], records, "badpix_0.07", tmp_path / "beta.png",
                                MATHTEXT_BREAKER, MATHTEXT_BREAKER, MATHTEXT_BREAKER, descending=True))
    points = Points(frame["test_s"].tolist(), frame["badpix_0.07"].tolist(), ["0.5", "1"],
                    list(frame["interpolation"]), MATHTEXT_BREAKER, MATHTEXT_BREAKER)
    written.append(accuracy_vs_time(points, points, "badpix_0.07", tmp_path / "acc.png", MATHTEXT_BREAKER,
                                    MATHTEXT_BREAKER))
    sweep = pd.DataFrame({"interpolation": [MATHTEXT_BREAKER] * 2, "sub-pixel fit": ["$a$", "$a$"],
                          "interval (px)": [1.0, 0.5], get_metric("badpix_0.07").label: [20.0, 10.0]},
                         index=pd.Index([MATHTEXT_BREAKER] * 2, name="scenes"))
    written.append(sweep_figure(sweep, tmp_path / "sweep.png"))
    assert all(Path(p).stat().st_size > 1000 for p in written)


def test_log_axis_ticks_are_plain_text(tmp_path):
    """Under plain text, matplotlib's default log tick labels ($\\mathdefault{10^{0}}$) would show their
    markup: the learning curve's loss axis labels its ticks as plain numbers."""
    from lfbench.reports.plotting import pyplot
    from lfbench.utils.figure_text import plain_log_ticks, plain_text

    labels = []

    @plain_text
    def draw():
        plt = pyplot()
        fig, ax = plt.subplots()
        ax.plot([0, 1], [0.01, 10])
        ax.set_yscale("log")
        plain_log_ticks(ax.yaxis)
        fig.canvas.draw()
        labels.extend(t.get_text() for t in ax.get_yticklabels() if t.get_text())
        plt.close(fig)

    draw()
    assert labels and not any("$" in t or "\\" in t for t in labels)
    assert "1" in labels and "10" in labels


def test_an_error_naming_a_file_with_a_line_break_is_one_line(tmp_path, capsys):
    """The error line escapes control characters of the path it names (and of the message)."""
    from helpers import assert_one_error_line

    folder = tmp_path / "data" / "training" / "bad\nname\x1b[31m"
    folder.mkdir(parents=True)
    (folder / "parameters.cfg").write_text("\x00 not a cfg", encoding="utf-8")
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", "gt", "--out", tmp_path / "o")
    assert_one_error_line(rc, err, "bad\\nname\\x1b[31m", "parameters.cfg")
    assert "\x1b" not in err


# --------------------------------------------------------------------------- names that would share a file (class 4)

def test_file_name_rule():
    from lfbench.utils.names import MAX_NAME_BYTES, file_name

    assert file_name("planesweep:interval=0.25") == "planesweep_interval=0.25"
    assert file_name("m<1") == file_name("m>1") == "m_1"
    assert [file_name(x) for x in ("", ".", "..", "...", "a/../b")] == ["_", "_", "__", "___", "a_.._b"]
    long = "published:path=/" + "x" * 400
    name = file_name(long)
    assert len(name.encode()) <= MAX_NAME_BYTES and name == file_name(long) != file_name(long + "y")
    assert name.startswith("published_path=_xxx") and re.fullmatch(r".*-[0-9a-f]{12}", name)
    wide = file_name("é" * 200)  # cut on a character, not inside one
    assert len(wide.encode()) <= MAX_NAME_BYTES and wide.startswith("éé")


def test_file_names_refuse_two_labels_of_one_file():
    from lfbench.utils.errors import DataError
    from lfbench.utils.names import FileNames, file_names

    assert file_names(["b", "a", "b"], "method label") == {"b": "b", "a": "a"}
    with pytest.raises(DataError, match=r"method label: 'm<1' and 'm>1' would share the file name 'm_1'"):
        file_names(["m<1", "ok", "m>1"], "method label")
    with pytest.raises(DataError, match="'Gt' and 'gt'"):  # one file on macOS and Windows
        file_names(["Gt", "gt"], "method label")
    names = FileNames("method label", reserved=["header"])
    with pytest.raises(DataError, match="'Header' would have the file name 'Header', which lfbench uses there itself"):
        names("Header")


def _two_subs(tmp: Path, names: tuple[str, str]) -> list[str]:
    return [f"published:path={write_submission(tmp / n, {'s0': np.ones((SIZE, SIZE), np.float32)})}" for n in names]


@pytest.fixture()
def one_scene(tmp_path) -> Path:
    write_scene(tmp_path / "data", "s0", "training", size=SIZE)
    return tmp_path / "data"


@pytest.mark.parametrize(("methods", "fragments"), [
    (("SUBS", ("m<1", "m>1")), ("published:m<1", "published:m>1", "'published_m_1'")),
    (("SUBS", ("Sub", "sub")), ("published:Sub", "published:sub")),
    ((), ("'gt'", "twice")),
], ids=["label-chars", "label-case", "given-twice"])
def test_evaluate_refuses_methods_of_one_file_before_any_work(tmp_path, capsys, one_scene, methods, fragments):
    from helpers import assert_one_error_line

    specs = _two_subs(tmp_path, methods[1]) if methods else ["gt", "gt"]
    args = [a for spec in specs for a in ("--method", spec)]
    rc, _, err = run_cli(capsys, "evaluate", "--data", one_scene, *args, "--out", tmp_path / "out", "--save-maps")
    assert_one_error_line(rc, err, *fragments)
    assert not (tmp_path / "out").exists()


@pytest.fixture()
def twins(tmp_path) -> Path:
    for category, seed in (("stratified", 0), ("training", 1)):
        write_scene(tmp_path / "data", "twin", category, size=SIZE, seed=seed)
    write_scene(tmp_path / "data", "other", "training", size=SIZE, seed=2)
    return tmp_path / "data"


def test_two_scenes_of_one_name_are_refused_naming_both_folders(tmp_path, capsys, twins):
    """stratified/twin and training/twin would give duplicate (method, scene, metric) records: evaluate
    refuses them before any work (naming both folders) and runs with one category selected."""
    from helpers import assert_one_error_line

    for scenes in ([], ["--scenes", "twin"], ["--scenes", "stratified,training"]):
        rc, _, err = run_cli(capsys, "evaluate", "--data", twins, *scenes, "--method", "gt", "--out", tmp_path / "out")
        assert_one_error_line(rc, err, "two scenes are named 'twin'", str(twins / "stratified" / "twin"),
                              str(twins / "training" / "twin"))
        assert not (tmp_path / "out").exists()
    rc, _, err = run_cli(capsys, "evaluate", "--data", twins, "--scenes", "training", "--method", "gt", "--out",
                         tmp_path / "out", "--no-progress", "--html")  # the site shows the scenes scored
    assert rc == 0, err
    assert (tmp_path / "out" / "html" / "scene-twin.html").is_file()


def test_report_with_maps_on_a_root_of_two_same_named_scenes(tmp_path, capsys, twins):
    """Results of training/twin, reported with maps from a root that also holds stratified/twin: the
    report cannot tell which folder the results mean, refuses, and works given the category folder."""
    from helpers import assert_one_error_line

    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "evaluate", "--data", twins, "--scenes", "training", "--method", "gt", "--out", out,
                         "--save-maps", "--no-progress")
    assert rc == 0, err
    rc, _, err = run_cli(capsys, "report", out, "--out", tmp_path / "rep", "--maps", out / "maps")
    assert_one_error_line(rc, err, "two scenes are named 'twin'", "--data ROOT/CATEGORY")
    rc, _, err = run_cli(capsys, "report", out, "--out", tmp_path / "rep", "--maps", out / "maps", "--data",
                         twins / "training")
    assert rc == 0, err
    assert (tmp_path / "rep" / "figures" / "overview_twin.png").is_file()


def test_scenes_of_one_file_name_are_refused(tmp_path, capsys):
    from helpers import assert_one_error_line

    for name in ("a<b", "a>b"):
        write_scene(tmp_path / "data", name, "training", size=SIZE)
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "data", "--method", "gt", "--out", tmp_path / "out")
    assert_one_error_line(rc, err, "scene: 'a<b' and 'a>b'", "'a_b'")


def _results_file(tmp: Path, records: list[tuple[str, str]]) -> Path:
    import json

    path = tmp / "r" / "results.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"records": [{"method": m, "scene": s, "metric": "badpix_0.07", "value": 1.0,
                                             "resolution": "lowres"} for m, s in records]}), encoding="utf-8")
    return path


@pytest.mark.parametrize(("records", "fragments"), [
    ([("m<1", "s"), ("m>1", "s")], ("method label: 'm<1' and 'm>1'",)),
    ([("m", "s<1"), ("m", "s>1")], ("scene: 's<1' and 's>1'",)),
    ([("m", "twin"), ("m", "twin")], ("record m/twin/badpix_0.07 appears twice",)),
], ids=["methods", "scenes", "duplicate-record"])
@pytest.mark.parametrize("command", ["report", "report-html", "regress"])
def test_results_read_back_with_colliding_names_are_refused(tmp_path, capsys, records, fragments, command):
    """report and regress refuse alike what evaluate refuses before it runs."""
    from helpers import assert_one_error_line

    path = _results_file(tmp_path, records)
    argv = {"report": ["report", path, "--out", tmp_path / "rep"],
            "report-html": ["report", path, "--out", tmp_path / "rep", "--html"],
            "regress": ["regress", _results_file(tmp_path / "g", [("m", "s")]), path]}[command]
    rc, _, err = run_cli(capsys, *argv)
    assert_one_error_line(rc, err, str(path), *fragments)
    assert not (tmp_path / "rep").exists()


def test_ablation_methods_of_one_folder_or_a_cell_id_are_refused(tmp_path, capsys):
    from helpers import assert_one_error_line
    from test_ablate import write_spec

    from lfbench.ablation.spec import load_spec
    from lfbench.utils.errors import LFBenchError

    tail = '[[methods]]\nlabel = "m<1"\nspec = "constant"\n[[methods]]\nlabel = "m>1"\nspec = "gt"\n'
    spec = tmp_path / "a" / "spec.toml"
    spec.parent.mkdir()
    spec.write_text("[evaluation]\nsynthetic = { seed = 5, size = 48, scenes = 1 }\n" + tail, encoding="utf-8")
    rc, _, err = run_cli(capsys, "ablate", spec, "--out", tmp_path / "ab")
    assert_one_error_line(rc, err, "spec.toml", "'m<1' and 'm>1'", "'m_1'")
    assert not (tmp_path / "ab").exists()
    with pytest.raises(LFBenchError, match="label 'base' is also the id of a cell"):
        load_spec(write_spec(tmp_path / "b", "", '[[methods]]\nlabel = "base"\nspec = "gt"\n'))
    with pytest.raises(LFBenchError, match="'base' and 'Base'"):  # the HTML pages of the two
        load_spec(write_spec(tmp_path / "c", "", '[[methods]]\nlabel = "Base"\nspec = "gt"\n'))


def test_figure_writer_refuses_a_row_named_like_its_own_files(tmp_path):
    from lfbench.data.hci import HCIScene
    from lfbench.reports.figures import SceneFigureWriter
    from lfbench.utils.errors import DataError

    scene = HCIScene(write_scene(tmp_path / "data", "s0", "training", size=SIZE))
    writer = SceneFigureWriter(tmp_path / "fig", curves=False)
    writer.add("m<1", scene, np.ones((SIZE, SIZE), np.float32))
    with pytest.raises(DataError, match="'m<1' and 'm>1'"):
        writer.add("m>1", scene, np.zeros((SIZE, SIZE), np.float32))
    with pytest.raises(DataError, match="'header' would have the file name 'header'"):
        writer.add("header", scene, np.zeros((SIZE, SIZE), np.float32))
    assert sorted(p.name for p in (tmp_path / "fig" / "s0").iterdir()) == ["header.png", "m_1.png"]


def test_toolkit_pairwise_names_of_one_file_are_refused_before_drawing(tmp_path):
    """'a_vs_b' vs 'c' and 'a' vs 'b_vs_c' are both pairwise_a_vs_b_vs_c."""
    from lfbench.data.hci import HCIScene
    from lfbench.reports.maps import load_scene_maps
    from lfbench.reports.toolkit_figures import toolkit_figures_from_scene_maps
    from lfbench.results import Record, Results
    from lfbench.utils.errors import DataError

    scene = HCIScene(write_scene(tmp_path / "data", "s0", "training", size=SIZE))
    labels = ["a_vs_b", "c", "a", "b_vs_c"]
    folders = {m: write_submission(tmp_path / f"sub{i}", {"s0": np.full((SIZE, SIZE), i, np.float32)})
               for i, m in enumerate(labels)}
    results = Results([Record(m, "s0", "badpix_0.07", 1.0, "lowres") for m in labels])
    with pytest.raises(DataError, match="method pair: 'a_vs_b vs c' and 'a vs b_vs_c'"):
        toolkit_figures_from_scene_maps(results, [load_scene_maps(scene, folders)], tmp_path / "tk")
    assert not (tmp_path / "tk").exists()


def test_training_stage_names_are_file_names(tmp_path):
    from lfbench.training.config import TrainConfig
    from lfbench.training.run_folder import stage_weights_name
    from lfbench.utils.errors import LFBenchError

    assert stage_weights_name(0, "../../escape") == "stage1_.._.._escape.pt"

    def config(*names: str) -> dict:
        return {"data": {"roots": [str(tmp_path)]},
                "stages": [{"name": n, "loss": "l1", "lr": 1e-3, "steps": 1} for n in names]}

    TrainConfig.from_dict(config("l1", "a/b"))
    with pytest.raises(LFBenchError, match="stage name: 'a/b' and 'a:b'"):
        TrainConfig.from_dict(config("a/b", "a:b"))
