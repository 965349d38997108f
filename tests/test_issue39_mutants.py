"""Tests for the survivors of issue 39's mutation run (results/mutation/issue39/README.md): the scorer policy and
a protocol's scoring, the lfbench-dataset.toml declarations (lfbench.data.dataset_file), the SYNTHETIC marker
(lfbench.data.provenance) and the statistics' tiles and ties (lfbench.scoring.stats). Every expected value is
written by hand from the rule the docstrings state, or taken from an independent computation (a brute-force
count, a hand enumeration); each test names the mutants' class it kills."""

from __future__ import annotations

import itertools
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from lfbench.data import dataset_file
from lfbench.data.dataset import DatasetProtocol
from lfbench.data.dataset_file import (
    GroundTruthSection,
    ProtocolSection,
    ViewsSection,
    file_name_problem,
    pattern_problem,
)
from lfbench.data.provenance import SYNTHETIC_MARKER, is_synthetic_root, mark_synthetic
from lfbench.data.scene import HIGHRES, LOWRES
from lfbench.scoring.metrics import get_metric
from lfbench.scoring.pixels import PixelErrors
from lfbench.scoring.policy import LFBENCH, PAPER_AUTHOR, ScorerPolicy, scorer
from lfbench.scoring.prepare import SceneReference
from lfbench.scoring.protocol import protocol_scoring
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.stats import ScoredErrors, _signflip_p, block_groups, bootstrap_replicates
from lfbench.utils.errors import SpecError
from lfbench.utils.options import Table, parse_section

# --------------------------------------------------------------------------- lfbench-dataset.toml declarations


@pytest.mark.parametrize(("value", "expected"), [
    ("", "must be a file name inside the scene folder, got ''"),
    ("a/b.png", "must be a file name inside the scene folder, got 'a/b.png'"),
    ("a\\b.png", "must be a file name inside the scene folder, got 'a\\\\b.png'"),
    (".", "must be a file name inside the scene folder, got '.'"),
    ("..", "must be a file name inside the scene folder, got '..'"),
    ("/" + "x" * 80, "must be a file name inside the scene folder, got '/" + "x" * 59 + "'"),  # 60 characters shown
    ("gt.npy", None), ("...", None), (".gt", None), ("a.b.pfm", None),
])
def test_file_name_problem_word_for_word(value, expected):
    """Each of the four refusals and its message (the value cut to 60 characters); names that only look like
    '.' or '..' are file names. Kills: a dropped or inverted clause, a changed tuple, the message or the cut."""
    assert file_name_problem(value) == expected


@pytest.mark.parametrize(("pattern", "expected"), [
    # not a file name: file_name_problem's own message
    ("../v{k}.png", "must be a file name inside the scene folder, got '../v{k}.png'"),
    # braces
    ("v{k.png", "has unbalanced braces: 'v{k.png'"),
    ("v}{k}.png", "has unbalanced braces: 'v}{k}.png'"),
    ("v{k" + "x" * 80, "has unbalanced braces: 'v{k" + "x" * 57 + "'"),
    # fields other than a bare {v}, {u}, {k}: the field shown as written
    ("v{0}.png", "may hold only the fields {v}, {u} and {k} (no format spec); got '{0}'"),
    ("v{}.png", "may hold only the fields {v}, {u} and {k} (no format spec); got '{}'"),
    ("v{x}_{u}.png", "may hold only the fields {v}, {u} and {k} (no format spec); got '{x}'"),
    ("v{k!r}.png", "may hold only the fields {v}, {u} and {k} (no format spec); got '{k!r}'"),
    ("v{k:>9}.png", "may hold only the fields {v}, {u} and {k} (no format spec); got '{k:>9}'"),
    ("v{k!s:>9}.png", "may hold only the fields {v}, {u} and {k} (no format spec); got '{k!s:>9}'"),
    ("v{k:" + "9" * 50 + "}.png", "may hold only the fields {v}, {u} and {k} (no format spec); got '{k:"
     + "9" * 37 + "'"),  # 40 characters shown
    # which fields
    ("v{u}.png", "must name a view by {v} and {u} (row, column) or by {k}, e.g. 'view_{v}_{u}.png'; got 'v{u}.png'"),
    ("v{v}.png", "must name a view by {v} and {u} (row, column) or by {k}, e.g. 'view_{v}_{u}.png'; got 'v{v}.png'"),
    ("v{v}_{u}_{k}.png",
     "must name a view by {v} and {u} (row, column) or by {k}, e.g. 'view_{v}_{u}.png'; got 'v{v}_{u}_{k}.png'"),
    ("v{u}_{k}.png",
     "must name a view by {v} and {u} (row, column) or by {k}, e.g. 'view_{v}_{u}.png'; got 'v{u}_{k}.png'"),
    ("view.png", "must name a view by {v} and {u} (row, column) or by {k}, e.g. 'view_{v}_{u}.png'; got 'view.png'"),
    # a PNG
    ("v{k}.jpg", "must name PNG files, got 'v{k}.jpg'"),
    ("v{k}png", "must name PNG files, got 'v{k}png'"),
    # accepted
    ("v{k}.png", None), ("v{k}.PNG", None), ("view_{v}_{u}.png", None), ("{u}-{v}.Png", None),
    ("v{k}_{k}.png", None),
])
def test_pattern_problem_word_for_word(pattern, expected):
    """Every refusal of a view pattern with its exact message, in the order the docstring gives (file name,
    braces, bare fields, {v}+{u} or {k}, PNG), and patterns it accepts (any case of '.png', a field twice).
    Kills: each clause dropped or inverted, the field tuple or set changed, the shown field built otherwise, a
    cut changed, a message changed, ``lower()`` dropped."""
    assert pattern_problem(pattern) == expected


def _section(cls, raw: dict, where: str = "views"):
    return parse_section(cls, Table(raw, where, "lfbench-dataset.toml"))


def test_views_transpose_needs_a_square_grid_and_the_values_pass_through():
    """check_options: transpose on a 3x5 grid is refused naming the key and the grid as rows x columns; on a
    square grid, or without transpose, the values are kept as read. Kills: the condition's `and` / `!=`, the
    unpacked names swapped, the key or message changed, the values dropped."""
    with pytest.raises(SpecError, match=r"^lfbench-dataset\.toml: views\.transpose: needs a square grid of views, "
                                        r"got 3x5$"):
        _section(ViewsSection, {"pattern": "v{k}.png", "angular": [3, 5], "transpose": True})
    with pytest.raises(SpecError, match="got 5x3$"):
        _section(ViewsSection, {"pattern": "v{k}.png", "angular": [5, 3], "transpose": True})
    square = _section(ViewsSection, {"pattern": "v{k}.png", "angular": 3, "transpose": True})
    assert (square.angular, square.transpose, square.pattern) == ((3, 3), True, "v{k}.png")
    flat = _section(ViewsSection, {"pattern": "v{v}_{u}.png", "angular": [3, 5]})
    assert (flat.angular, flat.transpose, flat.first) == ((3, 5), False, 0)


@pytest.mark.parametrize(("raw", "fmt"), [
    ({}, "npy"),  # no file: npy
    ({"file": "gt"}, "npy"),  # no suffix: npy
    ({"file": "gt.PFM"}, "pfm"),  # the suffix, lower-cased
    ({"file": "disp.v2.npy"}, "npy"),  # the last suffix only
    ({"file": "gt.png", "format": "png16"}, "png16"),  # a declared format wins over the suffix
    ({"file": "gt.pfm", "format": "npy"}, "npy"),
])
def test_ground_truth_format_from_the_file_suffix(raw, fmt):
    """GroundTruthSection.check_options: the format is the declared one, else the file's last suffix in lower case,
    else npy. Kills: rsplit -> split / maxsplit changed, [-1] -> another index, lower() dropped, the default 'npy'
    changed, the `and` / `in` conditions changed, the returned dict's key."""
    section = _section(GroundTruthSection, raw, "ground_truth")
    assert section.format == fmt
    assert section.file == raw.get("file")


def test_ground_truth_format_refused_word_for_word():
    with pytest.raises(SpecError, match=r"^lfbench-dataset\.toml: ground_truth\.format: must be one of pfm, npy, "
                                        r"png16, got 'tif'$"):
        _section(GroundTruthSection, {"file": "d.TIF"}, "ground_truth")
    with pytest.raises(SpecError, match="got '" + "x" * 40 + "'$"):
        _section(GroundTruthSection, {"file": "d.png", "format": "x" * 50}, "ground_truth")


@pytest.mark.parametrize(("rng", "step", "message"), [
    ([0.0, 1.0], 1.0, None),  # exactly the range: allowed
    ([0.0, 1.0], 0.5, None),
    ([-2.0, 2.0], None, None),
    ([0.0, 1.0], 1.25, "must be at most the range's max - min (1), got 1.25"),
    ([-1.5, 1.0], 3.0, "must be at most the range's max - min (2.5), got 3"),
])
def test_protocol_interval_at_most_the_range(rng, step, message):
    """ProtocolSection.check_options: the interval may equal max - min, not exceed it; the message shows both
    with :g. Kills: `>` -> `>=`, `high - low` -> `high + low`, low and high swapped, the `is not None` test,
    the key or message changed."""
    raw = {"disparity_range": rng} | ({} if step is None else {"disparity_interval": step})
    if message is None:
        section = _section(ProtocolSection, raw, "protocol")
        assert section.disparity_range == tuple(rng) and section.disparity_interval == step
    else:
        with pytest.raises(SpecError) as info:
            _section(ProtocolSection, raw, "protocol")
        assert str(info.value) == f"lfbench-dataset.toml: protocol.disparity_interval: {message}"


@pytest.mark.parametrize(("rng", "message"), [
    ([1.0, 1.0], "must be [min, max] px with min < max, got [1.0, 1.0]"),
    ([2.0, -2.0], "must be [min, max] px with min < max, got [2.0, -2.0]"),
    ([-0.5, 1.6], None),
])
def test_disparity_range_needs_min_below_max(rng, message):
    """_range_problem through the reader: an empty or reversed range is refused with both ends shown. Kills: `<`
    -> `<=`, the indices, the message."""
    if message is None:
        assert _section(ProtocolSection, {"disparity_range": rng}, "protocol").disparity_range == tuple(rng)
    else:
        with pytest.raises(SpecError) as info:
            _section(ProtocolSection, {"disparity_range": rng}, "protocol")
        assert str(info.value) == f"lfbench-dataset.toml: protocol.disparity_range: {message}"


def test_main_prints_the_reference(capsys):
    """``python -m lfbench.data.dataset_file`` prints reference() as it is and exits 0."""
    assert dataset_file.main() == 0
    assert capsys.readouterr().out == dataset_file.reference()
    assert dataset_file.reference().startswith("<!-- Generated by `python -m lfbench.data.dataset_file > "
                                               "docs/dataset-toml.md`")


# --------------------------------------------------------------------------- the SYNTHETIC marker


def test_mark_synthetic_writes_the_marker_naming_the_command(tmp_path):
    """The marker is ROOT/SYNTHETIC, a short text naming the command (for the person who opens the folder).
    Kills: the path or text changed."""
    path = mark_synthetic(str(tmp_path), "lfbench synth --seed 0")
    assert path == tmp_path / "SYNTHETIC" and SYNTHETIC_MARKER == "SYNTHETIC"
    assert path.read_text(encoding="utf-8") == ("Written by lfbench synth --seed 0: synthetic scenes with exact "
                                                "ground truth, not a real dataset.\n")


def test_is_synthetic_root_of_one_root_as_str_or_path_and_of_several(tmp_path, monkeypatch):
    """One root as str or Path (never iterated character by character), several roots in any order, a missing
    root or one that is a file skipped. Kills: the str | Path test changed, `return True` -> False,
    `continue` -> `break`, lstat -> another path."""
    marked, plain = tmp_path / "marked", tmp_path / "plain"
    marked.mkdir()
    plain.mkdir()
    (marked / SYNTHETIC_MARKER).write_text("x")
    (plain / "file").write_text("x")
    assert is_synthetic_root(str(marked)) is True and is_synthetic_root(marked) is True
    assert is_synthetic_root(str(plain)) is False and is_synthetic_root(plain) is False
    assert is_synthetic_root([tmp_path / "missing", plain / "file", marked]) is True
    assert is_synthetic_root((str(plain), str(marked))) is True
    assert is_synthetic_root([plain, tmp_path / "missing"]) is False
    assert is_synthetic_root([]) is False
    monkeypatch.chdir(tmp_path)
    assert is_synthetic_root("marked") is True and is_synthetic_root(Path("plain")) is False


# --------------------------------------------------------------------------- the scorer policy and a protocol's scoring


def test_scorer_names_its_choices_word_for_word():
    """scorer(): each policy by its name; an unknown name is one ValueError naming the choices, comma-separated.
    Kills: the join's separator, the message, the membership test."""
    assert scorer("lfbench") is LFBENCH and scorer("paper-author") is PAPER_AUTHOR
    with pytest.raises(ValueError) as info:
        scorer("strict")
    assert str(info.value) == "unknown scorer 'strict'; choose from lfbench, paper-author"


_PROTOCOL = DatasetProtocol(border_px=7, metrics=("mse_x100", "badpix_0.03"), disparity_range=(-1.0, 3.0),
                            disparity_interval=0.5, resolutions=(LOWRES, HIGHRES), highres_scenes=frozenset({"a"}),
                            scorer="paper-author")


def test_protocol_scoring_defaults_and_meta():
    """protocol_scoring's defaults: lfbench's non-finite rule (toolkit False), high resolution allowed where the
    protocol has it, no extra metric; the metrics are exactly the protocol's, in its order; meta() records them
    as ``protocol_metrics``. Kills: each default flipped, meta's key or list changed."""
    scoring = protocol_scoring(_PROTOCOL)
    assert scoring.rules == ScoringRules(border_px=7, highres_scenes=frozenset({"a"}), toolkit=False,
                                         allow_highres=True, scorer="paper-author")
    assert [m.id for m in scoring.metrics] == ["mse_x100", "badpix_0.03"]
    assert scoring.meta() == {"protocol_metrics": ["mse_x100", "badpix_0.03"]}
    assert scoring.protocol is _PROTOCOL


def test_protocol_scoring_passes_its_options_on():
    """toolkit, allow_highres and extra reach the rules and the metrics; the grid is the protocol's range and
    interval. Kills: an argument dropped or replaced by its default."""
    scoring = protocol_scoring(_PROTOCOL, toolkit=True, allow_highres=False, extra=["badpix_0.07", "mse_x100"])
    assert scoring.rules == ScoringRules(border_px=7, highres_scenes=frozenset({"a"}), toolkit=True,
                                         allow_highres=False, scorer="paper-author")
    assert [m.id for m in scoring.metrics] == ["mse_x100", "badpix_0.03", "badpix_0.07"]
    lowres_only = DatasetProtocol(border_px=0, metrics=("mse_x100",), disparity_range=(0.0, 1.0))
    assert protocol_scoring(lowres_only).rules.allow_highres is False  # the protocol has no high resolution
    assert protocol_scoring(lowres_only).rules.scorer == "lfbench"

    class Param:
        def __init__(self, default):
            self.default = default

    class Info:
        params = {"d_min": Param(-4.0), "d_max": Param(4.0), "interval": Param(0.25)}
        method_class = object

    # the method's grid from d_min = -1 at 0.5 px: d_max is the first grid point at or above 3, i.e. 3
    assert scoring.grid(Info(), {}) == {"d_min": -1.0, "d_max": 3.0, "interval": 0.5}


@pytest.mark.parametrize(("scoring", "message"), [
    ([1], "'scoring' must be an object"),
    ({"border_px": True}, "'scoring.border_px' must be an integer >= 0"),
    ({"border_px": -1}, "'scoring.border_px' must be an integer >= 0"),
    ({"border_px": 3.0}, "'scoring.border_px' must be an integer >= 0"),
    ({"highres_scenes": "a"}, "'scoring.highres_scenes' must be a list of scene names"),
    ({"highres_scenes": ["a", 1]}, "'scoring.highres_scenes' must be a list of scene names"),
    ({"toolkit_nonfinite": 1}, "'scoring.toolkit_nonfinite' must be true or false"),
    ({"scorer": "strict"}, "'scoring.scorer' must be one of lfbench, paper-author"),
])
def test_rules_from_meta_refuse_word_for_word(scoring, message):
    """A results file's recorded rules of the wrong type: one ValueError naming the key. Kills: each condition's
    `or` -> `and`, `< 0` -> `<= 0`, a message changed or dropped."""
    with pytest.raises(ValueError) as info:
        ScoringRules.from_meta({"scoring": scoring})
    assert str(info.value) == message


def test_rules_from_meta_read_every_recorded_key():
    """Each recorded key is read under its own name (border 0 included), what is not recorded keeps its default,
    and overrides win. Kills: a key's name changed, `< 0` -> `< 1`."""
    recorded = {"border_px": 0, "highres_scenes": ["b", "a"], "toolkit_nonfinite": True, "scorer": "paper-author"}
    assert ScoringRules.from_meta({"scoring": recorded}) == ScoringRules(
        border_px=0, highres_scenes=frozenset({"a", "b"}), toolkit=True, scorer="paper-author")
    assert ScoringRules.from_meta({"scoring": {"border_px": 5}}, toolkit=True) == ScoringRules(border_px=5,
                                                                                              toolkit=True)
    assert ScoringRules.from_meta({"scoring": {"highres_scenes": []}}).highres_scenes == frozenset()
    assert ScoringRules.from_meta({}) == ScoringRules() == ScoringRules.from_meta({"scoring": None})


def test_rules_of_protocol_defaults():
    """ScoringRules.of_protocol's own defaults (protocol_scoring always passes them): lfbench's non-finite rule and
    high resolution where the protocol has it. Kills: each default flipped."""
    rules = ScoringRules.of_protocol(_PROTOCOL)
    assert (rules.toolkit, rules.allow_highres, rules.highres_scenes, rules.border_px) == (False, True,
                                                                                           frozenset({"a"}), 7)


# errors |pred - gt| on 8 pixels: 0.5 twice (ties with t = 0.5), 0.25, 1.0, 0, a NaN and an inf prediction, and a
# pixel whose ground truth is NaN (pred 0)
_GT = np.array([[0, 0, 0, 0], [0, 0, 0, np.nan]], np.float32)
_PRED = np.array([[0.5, -0.5, 0.25, 1.0], [0.0, np.nan, np.inf, 0.0]], np.float32)


@pytest.mark.parametrize(("policy", "badpix", "mse"), [
    # lfbench's rule: 7 pixels with finite gt; bad: 1.0, NaN, inf; MSE over the 5 finite pixels
    (LFBENCH, 100 * 3 / 7, 100 * (0.25 + 0.25 + 0.0625 + 1.0) / 5),
    # a policy declaring neither change is lfbench's rule, whatever its name
    (ScorerPolicy("plain", inclusive=False, nan_good=False, source="-"), 100 * 3 / 7,
     100 * (0.25 + 0.25 + 0.0625 + 1.0) / 5),
    # >= t with lfbench's non-finite rule: the two ties, 1.0, NaN and inf of 7
    (ScorerPolicy("ties", inclusive=True, nan_good=False, source="-"), 100 * 5 / 7,
     100 * (0.25 + 0.25 + 0.0625 + 1.0) / 5),
    # the paper author's: every pixel (8), ties and inf bad, NaN (prediction or gt) good; MSE NaN
    (PAPER_AUTHOR, 100 * 4 / 8, float("nan")),
])
def test_each_declared_rule_of_a_policy_on_its_own(policy, badpix, mse):
    """BadPix and MSE under each combination of the policy's two flags, by hand. Kills: the `inclusive` test forced,
    `>` -> `>=` in the non-inclusive branch, lfbench's non-finite rule under a non-lfbench policy dropped or its
    `|` / `~` / kept mask changed."""
    px = PixelErrors.of_maps(_GT, _PRED)
    px.scorer = policy
    assert get_metric("badpix_0.5").score_pixels(px) == pytest.approx(badpix, rel=1e-12)
    got = get_metric("mse_x100").score_pixels(px)
    assert (np.isnan(got) and np.isnan(mse)) or got == pytest.approx(mse, rel=1e-6)


def test_mse_keeps_which_pixels_it_scored_for_the_tile_bootstrap():
    """MSE's sample keeps the positions of its finite pixels: a tile bootstrap over errors with non-finite pixels
    equals the one over the same errors with those pixels removed by hand (same tiles, same draws). Kills: the
    kept mask replaced by None."""
    errors = np.array([0.1, np.nan, 0.3, np.inf, 0.2, 0.4], np.float32)
    groups = np.array([0, 0, 1, 1, 2, 2])
    got = bootstrap_replicates(errors, "mse_x100", n=40, seed=3, groups=groups)
    finite = np.isfinite(errors)
    expected = bootstrap_replicates(errors[finite], "mse_x100", n=40, seed=3, groups=groups[finite])
    assert np.array_equal(got, expected) and np.unique(got).size > 1


def test_a_prepared_prediction_scores_each_region_under_the_protocols_scorer(tmp_path):
    """Prepared.errors(mask): the errors at the evaluation mask and the region mask (not the whole scene), with the
    protocol's scorer set on them. Kills: the mask name dropped, the scorer left lfbench's."""
    from helpers import write_scene

    from lfbench.data.hci import HCIScene

    region = np.zeros((40, 40), bool)
    region[15:20, 15:40] = True  # 5 x 10 of it inside the 15 px border
    scene = HCIScene(write_scene(tmp_path, "s", size=40, views=False, masks={"m_lowres": region}))
    pred = np.full((40, 40), 1.0, np.float32)
    pred[15:17] = 1.5  # 2 rows off by exactly 0.5: 20 of the 100 scored pixels, 20 of the region's 50
    for rules, policy, whole, inside in ((ScoringRules(), LFBENCH, 0.0, 0.0),
                                         (ScoringRules(scorer="paper-author"), PAPER_AUTHOR, 20.0, 40.0)):
        prepared = SceneReference(scene, rules).prepare(pred, LOWRES)
        assert prepared.errors().err.size == 100 and prepared.errors("m").err.size == 50
        assert prepared.errors("m").scorer is policy and prepared.errors().scorer is policy
        assert get_metric("badpix_0.5").score_pixels(prepared.errors()) == whole
        assert get_metric("badpix_0.5").score_pixels(prepared.errors("m")) == inside


# --------------------------------------------------------------------------- the statistics' tiles and ties


def _exact_signflip_p(x: list[Fraction]) -> float:
    """Two-sided sign-flip p-value in exact rational arithmetic: the share of the 2^k sign vectors s with
    |sum(s_i x_i)| >= |sum(x_i)| (ties count as at least as extreme)."""
    observed = abs(sum(x))
    hits = sum(abs(sum(s * v for s, v in zip(signs, x, strict=True))) >= observed
               for signs in itertools.product((1, -1), repeat=len(x)))
    return hits / 2 ** len(x)


@pytest.mark.parametrize("values", [
    ["1", "2", "3"],  # only the identity and the full flip reach 6: 2 / 8
    ["1", "1"],  # 2 / 4
    ["0.3", "-0.1", "-0.2", "0.6"],  # flipping {0.3, -0.1, -0.2} ties the observed 0.6 exactly, not in floats
    ["0.1", "0.2", "0.3", "-0.6", "0.7"],
    ["0", "0", "0"],  # every flip ties: p = 1
    # the same ties at a large scale: the tolerance is relative to sum |x| (1e-9 x 1.9e6, not 1e-9 / 1.9e6)
    ["100000.1", "200000.2", "300000.3", "-600000.6", "700000.7"],
    # a flip 2e-10 below the observed 0.0010000001 is no tie: the tolerance is not floored at 1e-9 absolute
    ["0.001", "0.0000000001"],
])
def test_signflip_p_counts_ties_as_extreme_by_exact_enumeration(values):
    """_signflip_p up to 16 units enumerates every flip; a flip whose |sum| equals the observed one in exact
    arithmetic counts, even where floating-point sums differ in the last bit (the relative tolerance). Kills: the
    tolerance dropped or of the wrong sign, `>=` -> `>`, abs() dropped, the enumeration's signs changed."""
    x = np.array([float(v) for v in values])
    assert _signflip_p(x, 10, np.random.default_rng(0)) == _exact_signflip_p([Fraction(v) for v in values])


def test_signflip_p_of_no_units_is_one():
    assert _signflip_p(np.array([]), 10, np.random.default_rng(0)) == 1.0


def test_signflip_p_enumerates_up_to_16_units_and_draws_beyond():
    """16 equal units: exactly 2 / 2^16 (the two flips that keep |sum| = 16); 17: Monte Carlo, p = (1 + hits) /
    (1 + n), and with n = 200 draws of a 2 / 2^17 event no hit: 1 / 201. Kills: `<=` -> `<` at the boundary, 16
    changed, the Monte Carlo p's `1 +` terms."""
    assert _signflip_p(np.ones(16), 200, np.random.default_rng(0)) == 2 / 2 ** 16
    assert _signflip_p(np.ones(17), 200, np.random.default_rng(0)) == 1 / 201


def test_signflip_p_monte_carlo_agrees_with_exact_enumeration():
    """18 units (Monte Carlo): p within 4.5 binomial standard errors of the exact enumeration of all 2^18 flips
    (numpy over every sign vector, independent of the draw). Kills: the flipped sum's `total - 2 x`, the bits
    unpacked from other bytes than the draw, hits miscounted."""
    x = np.random.default_rng(2).normal(0.3, 1.0, 18)  # 18 units: 3 bytes of 24 bits per draw, 6 unused
    signs = 1.0 - 2.0 * ((np.arange(2 ** 18)[:, None] >> np.arange(18)) & 1)
    exact = float(np.mean(np.abs(signs @ x) >= abs(x.sum()) * (1 - 1e-12)))
    assert 0.05 < exact < 0.95
    n = 4000
    got = _signflip_p(x, n, np.random.default_rng(1))
    assert abs(got - exact) < 4.5 * math.sqrt(exact * (1 - exact) / n) + 1 / n


def test_signflip_p_monte_carlo_counts_ties_over_every_chunk():
    """17 units of which 16 are 0: every flip ties the observed |sum| = 1, so p = (1 + n) / (1 + n) = 1, also when
    the n = 250000 draws come in two chunks (4 Mi elements each: 246723 draws of 17 units, then 3277). Kills: a tie
    not counted (`+ tol`), hits of the last chunk only (`=` for `+=`)."""
    x = np.zeros(17)
    x[5] = 1.0
    assert _signflip_p(x, 250000, np.random.default_rng(0)) == 1.0


def test_signflip_p_monte_carlo_flips_every_unit():
    """18 units: 16 of 0.01 and the pair 5, -5 (observed |sum| 0.16). A flip is at least as extreme exactly when the
    pair gets the same sign (|sum| >= 9.84; probability 1/2) or every sign stays as observed or is reversed
    (2 / 2^18), so p = 1/2 + 2^-17; a draw that never flips the last units (fewer random bits than units) gives
    about 1 / (1 + n). Kills: bytes per draw that give fewer than 18 bits."""
    x = np.array([0.01] * 16 + [5.0, -5.0])
    n = 2000
    assert abs(_signflip_p(x, n, np.random.default_rng(0)) - (0.5 + 2.0 ** -17)) < 4.5 * math.sqrt(0.25 / n)


@pytest.mark.parametrize("block", [None, 0, 1])
def test_block_of_one_pixel_or_none_is_no_tiling(block):
    """block None, 0 or 1: i.i.d. pixels (no groups) in both tilings. Kills: `<= 1` -> `< 1` / `<= 2`, `or` ->
    `and`."""
    mask = np.ones((4, 6), bool)
    assert block_groups(mask, block) is None
    assert ScoredErrors(np.zeros(24, np.float32), np.arange(24), (4, 6)).groups(block) is None
    assert block_groups(mask, 2) is not None


def test_tiles_of_two_by_hand():
    """block_groups and ScoredErrors.groups on a 3x5 mask in 2x2 tiles (3 tiles per row, rounded up), written
    out by hand; only the mask's True pixels, in row-major order."""
    mask = np.ones((3, 5), bool)
    mask[0, 1] = mask[2, 4] = False
    expected = [0, 1, 1, 2,
                0, 0, 1, 1, 2,
                3, 3, 4, 4]
    assert block_groups(mask, 2).tolist() == expected
    se = ScoredErrors(np.zeros(13, np.float32), np.flatnonzero(mask), (3, 5))
    assert se.groups(2).tolist() == expected
    assert block_groups(mask.astype(np.uint8) * 7, 2).tolist() == expected  # any non-zero is True
