"""The scoring core's mutants that the first full mutation run (results/mutation/full_run) left alive in the functions
it reached last: the scored pixels' rectangle (PixelSet's box, its check, and SceneReference's border box), the
prediction's values through ``take`` (columns out of order), the release of a region's errors after its last
metric in score_scene, the keywords a function of maps gets, the dtype a refused prediction's message names, a
link that leads nowhere, the bootstrap's errors of a prepared prediction under the toolkit's rules, and the
pixel-wise guard (OrderStatistic's range, the flag a plugin's sample gets, lfbench's own samples left unguarded,
the defaults). Each test names the mutants it kills; those no input can tell apart (a fast path that gives the same
values, an argument its callee already had) have their reasons in tools/mutation/classify.py.

In-process, small arrays, no CLI: every test here runs under mutmut's forked children.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import Anonymous, as_plugin, write_scene

from lfbench.data.hci import HCIScene
from lfbench.data.scene import ArrayLightField
from lfbench.scoring import prepare as prepare_module
from lfbench.scoring.base import Metric
from lfbench.scoring.general import abs_error_x100
from lfbench.scoring.pixels import PixelErrors, PixelSet
from lfbench.scoring.pixelwise import Mean, OrderStatistic, PixelMetric, Sample, _own
from lfbench.scoring.prepare import SceneReference, align_prediction, border_mask
from lfbench.scoring.rules import ScoringRules
from lfbench.scoring.score import score_scene
from lfbench.scoring.stats import ScoredErrors
from lfbench.utils.errors import DataError, LFBenchError
from lfbench.utils.readfile import check_regular_file, read_bytes, read_head

F32 = np.float32


# --------------------------------------------------------------------------- PixelSet's box


@pytest.mark.parametrize("box", [(3, 2, 0, 4), (-1, 2, 0, 4), (0, 4, 3, 2), (0, 4, -1, 2), (0, 5, 0, 4),
                                 (0, 4, 0, 5)])
def test_a_box_that_is_not_a_rectangle_of_the_map_is_refused(box):
    """PixelSet.__init__ mutants 19 and 26 (a bound of the rows or of the columns left unchecked): top after bottom,
    left after right, a negative start and an end past the map are each refused."""
    with pytest.raises(ValueError, match=r"^box .* is not a rectangle of the \(4, 4\) map$"):
        PixelSet(None, np.zeros((4, 4), F32), box=box)


@pytest.mark.parametrize("box", [(2, 2, 0, 4), (0, 4, 2, 2), (2, 2, 2, 2), (0, 4, 0, 4)])
def test_an_empty_or_whole_box_is_a_rectangle(box):
    """PixelSet.__init__ mutant 27 (``left < right``): an empty rectangle is one (a border of half the map scores no
    pixel), and so is the whole map; the set reads exactly the rectangle's pixels."""
    gt = np.arange(16, dtype=F32).reshape(4, 4)
    top, bottom, left, right = box
    pixels = PixelSet(None, gt, box=box)
    assert pixels.box == box and np.array_equal(pixels.gt, gt[top:bottom, left:right].ravel())
    assert pixels.size == (bottom - top) * (right - left)


def test_a_box_without_a_mask_selects_only_the_rectangle():
    """PixelSet.__init__ mutant 32 (the box dropped): a set given a box and no mask reads the rectangle, not the whole
    map; predictions too."""
    gt = np.arange(20, dtype=F32).reshape(4, 5)
    pixels = PixelSet(None, gt, box=(1, 3, 1, 4))
    assert np.array_equal(pixels.gt, gt[1:3, 1:4].ravel())
    assert np.array_equal(pixels.values(gt + 1), gt[1:3, 1:4].ravel() + 1)


def test_a_masked_set_with_columns_out_of_order_takes_each_pixels_column():
    """PixelSet.values mutants 13 (the first column taken as 1), 54 and 56 (``take`` along the flattened block): when
    the upsampling's columns do not run in order the values are taken column by column (``take``), for a set
    chosen by a mask as for a rectangle, the same values as indexing the upsampled map."""
    rng = np.random.default_rng(3)
    low = rng.standard_normal((4, 5)).astype(F32)
    rows = np.array([0, 0, 1, 1, 2, 2, 3, 3])
    cols = np.array([4, 3, 2, 1, 0, 0, 1, 2, 3, 4])  # not in order: no run of repeats
    full = low[rows][:, cols]
    mask = rng.random((8, 10)) < 0.6
    masked = PixelSet(mask, np.zeros((8, 10), F32), upsample=(rows, cols), low_width=5)
    boxed = PixelSet(border_mask((8, 10), 2), np.zeros((8, 10), F32), upsample=(rows, cols), low_width=5,
                     box=(2, 6, 2, 8))
    for block in (1, 3, 256):
        assert np.array_equal(masked.values(low, rows_per_block=block), full[mask])
        assert np.array_equal(boxed.values(low, rows_per_block=block), full[2:6, 2:8].ravel())


def test_a_prediction_narrower_than_the_sets_columns_is_an_index_error():
    """PixelSet.values mutants 22 (``first - size``), 25 (the height compared) and 26 (``repeats = ""``): a map narrower
    than the columns the set reads is refused by ``take``'s IndexError, never cut to fit (np.repeat of the columns
    it has would raise another error or, with other repeats, read the wrong pixels)."""
    rows, cols = np.zeros(2, np.intp), np.array([0, 1, 2, 3])  # columns 0..3 in order: a run of repeats
    pixels = PixelSet(None, np.zeros((2, 4), F32), upsample=(rows, cols), low_width=4)
    tall_and_narrow = np.zeros((8, 3), F32)  # 3 columns of the 4 read; taller than wide
    with pytest.raises(IndexError):
        pixels.values(tall_and_narrow)
    assert np.array_equal(pixels.values(np.arange(4, dtype=F32)[None].repeat(8, 0)), [0, 1, 2, 3, 0, 1, 2, 3])


# --------------------------------------------------------------------------- SceneReference


def _reference(border: int, size: tuple[int, int] = (12, 16)) -> SceneReference:
    gt = np.random.default_rng(1).uniform(-1, 1, size).astype(F32)
    views = np.zeros((3, 3, *size), F32)
    return SceneReference(ArrayLightField(views=views, name="toy", gt=gt), ScoringRules(border_px=border))


OBJECTS = np.zeros((12, 12), bool)
OBJECTS[2:6, 2:9] = True


def _masked_reference(tmp_path: Path) -> SceneReference:
    """A 12x12 HCI scene with the region mask ``objects`` (OBJECTS), a 2 px border."""
    folder = write_scene(tmp_path, "toy", size=12, views=False, masks={"objects_lowres": OBJECTS})
    return SceneReference(HCIScene(folder), ScoringRules(border_px=2))


@pytest.mark.parametrize(("border", "box"), [(0, (0, 12, 0, 16)), (2, (2, 10, 2, 14)), (5, (5, 7, 5, 11)),
                                             (6, (6, 6, 6, 10))])
def test_the_evaluation_pixels_of_a_scene_without_a_valid_mask_are_its_border_rectangle(border, box):
    """SceneReference._border_box mutants 8 (never a box), 12 and 13 (no box for a border of 0), 15 (``3 x border``)
    and 16 (no box when the border is half the height) and SceneReference.pixels mutants 22, 27 and 29 (no box): the
    scored pixels of a scene without a valid mask are sliced as the rectangle inside the border (issue 39.7's fast
    path), for every border up to half the scene's height, and that rectangle is exactly the evaluation mask."""
    reference = _reference(border)
    pixels = reference.pixels("lowres")
    top, bottom, left, right = box
    assert pixels.box == box
    inside = np.zeros((12, 16), bool)
    inside[top:bottom, left:right] = True
    assert np.array_equal(reference.evaluation_mask(), inside)
    assert np.array_equal(pixels.gt, reference.gt()[inside])


def test_a_region_mask_is_selected_by_its_mask_not_a_rectangle(tmp_path):
    """The other side of SceneReference.pixels: a region's pixels (a mask file) have no box, whatever the border."""
    reference = _masked_reference(tmp_path)
    assert reference.pixels("lowres").box == (2, 10, 2, 10)
    region = reference.pixels("lowres", "objects")
    assert region.box is None and region.size == int(np.count_nonzero(OBJECTS & border_mask((12, 12), 2)))


@pytest.mark.parametrize("region", [None, "objects"])
def test_releasing_a_region_drops_its_errors_and_a_region_never_gathered_is_no_error(tmp_path, region):
    """Prepared.release mutants 1 (the errors of the region without a mask dropped instead) and 3 (``pop`` without a
    default: KeyError): after release the region's errors are gathered again (a new object, the same values), the
    other region's are kept; releasing one never gathered does nothing."""
    reference = _masked_reference(tmp_path)
    prepared = reference.prepare(reference.gt() + F32(0.25), "lowres")
    prepared.release(None)  # nothing gathered yet
    prepared.release("objects")
    other = "objects" if region is None else None
    first, kept = prepared.errors(region), prepared.errors(other)
    assert prepared.errors(region) is first
    prepared.release(region)
    again = prepared.errors(region)
    assert again is not first and np.array_equal(again.err, first.err) and prepared.errors(other) is kept


@pytest.mark.parametrize("dtype", ["complex64", "bool", "<U3"])
def test_a_map_of_no_real_numbers_is_refused_naming_its_dtype(dtype):
    """align_prediction mutants 7 and 19 (the dtype's name lost): the line names the map and its dtype."""
    with pytest.raises(DataError, match=rf"^method X: disparity must be real floating-point values, got {dtype}$"):
        align_prediction(np.zeros((4, 4), dtype=dtype), (4, 4), "method X")


# --------------------------------------------------------------------------- score_scene


def _recording_metric(metric_id: str, log: list[str], *, pixelwise: bool) -> Metric:
    """A metric that appends its id to ``log`` when it computes: pixel-wise (a mean of |error|) or of maps."""

    def sample(px, *, toolkit=False):
        log.append(metric_id)
        return Sample(np.asarray(px.err, np.float64), None)

    def of_maps(gt, pred, mask=None, *, toolkit=False):  # no **context: a function that does not ask for the scene
        log.append(metric_id)
        return float(np.nanmean(np.abs(pred - gt)[mask]))

    sample.__module__ = of_maps.__module__ = "late_plugin"
    if pixelwise:
        return Metric(id=metric_id, name=metric_id, description="", unit="px",
                      pixelwise=PixelMetric(sample, Mean(1.0)))
    return Metric(id=metric_id, name=metric_id, description="", unit="px", fn=of_maps)


@pytest.fixture()
def log(monkeypatch) -> list[str]:
    """What happened, in order: the recording metrics append their ids, Prepared.release appends "release" (the
    region without a mask) or "release <mask name>"."""
    events: list[str] = []
    real_release = prepare_module.Prepared.release

    def release(self, mask_name=None):
        events.append("release" if mask_name is None else f"release {mask_name}")
        real_release(self, mask_name)

    monkeypatch.setattr(prepare_module.Prepared, "release", release)
    return events


@pytest.mark.parametrize(("kinds", "expected"), [
    ("pm", ["p0", "release", "m1"]),          # a function of maps after the last pixel-wise metric of the region
    ("pp", ["p0", "p1", "release"]),          # released after the last, not the first
    ("pmp", ["p0", "m1", "p2", "release"]),
])
def test_a_regions_errors_are_released_once_after_the_last_metric_that_reads_them(log, kinds, expected):
    """score_scene mutants 36 (functions of maps counted as readers), 37 (only they counted), 38 (only runtime
    metrics counted), 71 (the region never found), 72 (released after every other metric) and 73 (the region's
    name lost): the errors of a region are released once, right after the last pixel-wise metric that reads them,
    whatever comes after it, and the values are those of the metrics."""
    metrics = [_recording_metric(f"{kind}{k}", log, pixelwise=kind == "p") for k, kind in enumerate(kinds)]
    reference = _reference(2)
    score = score_scene(reference.scene, reference.gt() + F32(0.5), metrics, reference.rules, reference=reference)
    assert log == expected
    assert score.values == pytest.approx({m.id: 0.5 for m in metrics}, abs=1e-6)


def test_a_region_masks_errors_are_released_by_its_name(tmp_path, log):
    """score_scene mutant 73 (``release(None)``): a region metric's errors are released under the region's name."""
    reference = _masked_reference(tmp_path)
    plain = _recording_metric("p0", log, pixelwise=True)
    region = Metric(id="p1", name="p1", description="", unit="px", pixelwise=plain.pixelwise, mask_name="objects")
    score_scene(reference.scene, reference.gt(), [plain, region], reference.rules, reference=reference)
    assert log == ["p0", "release", "p0", "release objects"]  # p1 draws with p0's sample function


def test_a_function_of_maps_that_does_not_ask_for_the_scene_gets_no_scene(tmp_path):
    """score_scene mutant 76 (the scene always passed): a metric without ``needs_scene`` is called with the maps, the
    mask and ``toolkit`` only (a function without ``scene=`` works; one with it gets it when it asks)."""
    log: list[str] = []
    reference = _reference(2)
    seen: dict[str, object] = {}

    def asks(gt, pred, mask=None, *, toolkit=False, scene=None, resolution=None):
        seen.update(scene=scene, resolution=resolution)
        return 1.0

    asks.__module__ = "late_plugin"
    metrics = [_recording_metric("m0", log, pixelwise=False),
               Metric(id="m1", name="m1", description="", unit="px", fn=asks, needs_scene=True)]
    score = score_scene(reference.scene, reference.gt() + F32(0.5), metrics, reference.rules, reference=reference)
    assert score.values["m0"] == pytest.approx(0.5, abs=1e-6) and log == ["m0"]
    assert seen == {"scene": reference, "resolution": "lowres"}


# --------------------------------------------------------------------------- bounded reads


@pytest.mark.parametrize("read", [lambda p: read_bytes(p, "the scene's map"),
                                  lambda p: read_head(p, 4, "the scene's map"),
                                  lambda p: check_regular_file(p, "the scene's map")])
def test_a_link_that_leads_nowhere_is_named_with_its_path(tmp_path, read):
    """readfile._open mutants 27-29 (the message or the path lost): a dangling link is one line naming the link and
    what it should be."""
    link = tmp_path / "gt.npy"
    os.symlink(tmp_path / "absent.npy", link)
    with pytest.raises(DataError) as caught:
        read(link)
    assert str(caught.value) == f"{link}: the scene's map is a symbolic link that leads nowhere"
    assert caught.value.path == Path(link)


# --------------------------------------------------------------------------- the bootstrap's scored errors


def test_a_prepared_predictions_errors_under_the_toolkits_rules_keep_non_finite_ground_truth():
    """ScoredErrors.from_prepared mutant 6 (the toolkit flag not passed on): under the toolkit's rules every pixel
    of the mask is scored, non-finite ground truth too (its error NaN); by default those pixels are left out."""
    gt = np.array([[0.0, np.nan], [1.0, np.inf]], F32)
    prepared = SimpleNamespace(gt=gt, pred=np.ones((2, 2), F32), mask=np.ones((2, 2), bool), scale=1)
    own = ScoredErrors.from_prepared(prepared)
    toolkit = ScoredErrors.from_prepared(prepared, toolkit=True)
    assert np.array_equal(own.flat_index, [0, 2]) and np.array_equal(own.errors, [1.0, 0.0])
    assert np.array_equal(toolkit.flat_index, [0, 1, 2, 3]) and toolkit.toolkit is True
    assert np.array_equal(toolkit.errors[[0, 2]], [1.0, 0.0]) and np.isnan(toolkit.errors[1])
    assert np.isneginf(toolkit.errors[3])


# --------------------------------------------------------------------------- pixel-wise samples and their guard


def _errors(pred: list[float]) -> PixelErrors:
    gt = np.zeros(len(pred), F32)
    return PixelErrors.of_maps(gt[None], np.asarray(pred, F32)[None])


@pytest.mark.parametrize(("p", "shown"), [(250, "250"), (100, "100"), (100.0, "100.0"), (-0.5, "-0.5"),
                                          (True, "True"), ("25", "25"), (None, "None"),
                                          (1.0000000000000002e22, "1.0000000000000002e+")])
def test_an_order_statistic_outside_0_to_100_is_a_problem_naming_it(p, shown):
    """OrderStatistic.problem mutants 2 (`and` for the range's `or`), 3 (a bool let through), 8 and 9 (100
    accepted), 10 and 11 (the percentage's text lost or cut at 21 characters): a bool, a non-number, 100 and
    anything outside [0, 100) is a problem that shows the percentage's first 20 characters."""
    assert OrderStatistic(p).problem() == (f"OrderStatistic({shown}): the percentage must be a number from 0 to "
                                           "below 100")


@pytest.mark.parametrize("p", [0, 25, 99.999, 50.0])
def test_an_order_statistic_inside_0_to_100_is_no_problem(p):
    assert OrderStatistic(p).problem() is None


def test_a_plugins_family_with_a_problem_is_one_line_naming_the_plugin():
    """PixelMetric.draw mutants 2 (the family's problem ignored), 3 (its message lost) and 4 (the plugin not
    named): a plugin's OrderStatistic(250) is refused before its function runs, naming the function."""
    calls = []
    sample = as_plugin(lambda px, *, toolkit=False: calls.append(1) or Sample(px.err), "sample", module="my_plugin")
    with pytest.raises(LFBenchError) as caught:
        PixelMetric(sample, OrderStatistic(250)).draw(_errors([1.0, 2.0]))
    assert str(caught.value) == ("metric plugin my_plugin.sample: OrderStatistic(250): the percentage must be a "
                                 "number from 0 to below 100")
    assert calls == []


def test_a_plugins_sample_gets_the_toolkit_flag_it_is_drawn_with():
    """PixelMetric.draw mutants 14 and 16 (``toolkit`` None or left to the plugin's default): the plugin's function
    is called with the caller's flag."""
    seen = []
    sample = as_plugin(lambda px, *, toolkit="unset": seen.append(toolkit) or Sample(px.err), "sample",
                       module="my_plugin")
    metric = PixelMetric(sample, Mean(1.0))
    metric.draw(_errors([1.0]), toolkit=True)
    metric.draw(_errors([1.0]), toolkit=False)
    assert seen == [True, False]


def test_lfbenchs_own_sample_is_not_guarded_its_exceptions_keep_their_type():
    """_own mutants 2, 3, 9, 10, 12, 15 and 16 (an lfbench function not recognised) and PixelMetric.draw mutant 5
    (``_own(None)``): a sample function of an lfbench module is lfbench's code, called as it is; what it raises is
    a bug of lfbench (its own type and traceback), not a plugin's error line; a plugin's is that line."""

    def broken(px, *, toolkit=False):
        raise ZeroDivisionError("lfbench bug")

    own = PixelMetric(as_plugin(broken, "sample", module="lfbench.scoring.general"), Mean(1.0))
    with pytest.raises(ZeroDivisionError, match="^lfbench bug$"):
        own.draw(_errors([1.0]))
    assert _own(broken) and _own(as_plugin(lambda px: None, "sample", module="lfbench"))
    plugin = PixelMetric(as_plugin(broken, "sample", module="lfbench_extra.metrics"), Mean(1.0))
    line = r"^metric plugin lfbench_extra\.metrics\.sample failed: ZeroDivisionError: lfbench bug$"
    with pytest.raises(LFBenchError, match=line):
        plugin.draw(_errors([1.0]))
    assert not _own(as_plugin(lambda px: None, "sample", module="lfbench_extra")) and not _own(Anonymous())


def test_the_defaults_of_a_sample_are_lfbenchs_own_rules():
    """PixelMetric.draw mutant 1 and abs_error_x100 mutant 1 (``toolkit=True`` by default): drawn without the flag, a
    non-finite prediction is an infinite error (lfbench's rule); with ``toolkit=True`` it is left out."""
    px = _errors([0.5, np.nan, 1.0])
    metric = PixelMetric(abs_error_x100, OrderStatistic(25.0))
    for sample in (metric.draw(px), abs_error_x100(px)):
        assert np.array_equal(sample.values, [50.0, np.inf, 100.0]) and sample.keep is None
    toolkit = metric.draw(px, toolkit=True)
    assert np.array_equal(toolkit.values, [50.0, 100.0]) and np.array_equal(toolkit.keep, [True, False, True])


# --------------------------------------------------------------------------- what runs at import
# (mutmut's forked children never see these mutated when lfbench was imported before the fork: the tests build
# what they check in their own body, and tools/mutation/recheck_import_time.py runs them in fresh processes)


@pytest.mark.parametrize(("p", "word"), [(0, "0th"), (1, "1st"), (2, "2nd"), (3, "3rd"), (4, "4th"), (10, "10th"),
                                         (11, "11th"), (12, "12th"), (13, "13th"), (20, "20th"), (21, "21st"),
                                         (22, "22nd"), (23, "23rd"), (25.0, "25th"), (99, "99th"), (101, "101st"),
                                         (111, "111th"), (112, "112th"), (113, "113th"), (120, "120th"), (121, "121st"),
                                         (0.5, "0.5th"), (12.25, "12.25th")])
def test_a_quantiles_description_says_its_percentile_in_words(p, word):
    """_ordinal's mutants (the teens, the 1st / 2nd / 3rd suffixes, a fraction): English ordinals, as in a
    quantile metric's description (its tooltip and the metrics table of the pages)."""
    from lfbench.scoring.general import _ordinal, _quantile_metric

    assert _ordinal(p) == word
    if p < 100:
        metric = _quantile_metric(p, order=7)
        assert metric.description == f"{word} percentile of the absolute disparity error, x100."
        assert (metric.order, metric.id) == (7, f"q{p:g}_x100")


def _signed(value_range, higher_is_better=False) -> Metric:
    return Metric(id="x", name="x", description="", unit="px", fn=lambda gt, pred, mask=None, *, toolkit=False: 0.0,
                  signed=True, value_range=value_range, higher_is_better=higher_is_better)


@pytest.mark.parametrize("value_range", [(-1.0, 1.0), (-0.5, 0.25), (-np.inf, np.inf), (-1e-9, 1e-9)])
def test_a_signed_metric_ranges_over_both_sides_of_0(value_range):
    """Metric.__post_init__ mutants 27 (the range's test inverted) and 29 (``low < 1 < high``): a signed metric
    whose range holds values on both sides of 0 is accepted, whatever its size."""
    assert _signed(value_range).value_range == value_range


@pytest.mark.parametrize(("value_range", "higher_is_better"), [((0.0, 1.0), False), ((-1.0, 0.0), False),
                                                               ((1.0, 2.0), False), ((-1.0, 1.0), True)])
def test_a_signed_metric_that_is_not_best_at_0_is_refused_with_its_reason(value_range, higher_is_better):
    """Metric.__post_init__ mutants 26 (``and`` for ``or``), 28 (``low <= 0``), 30 (``0 <= high``) and 31 (the
    message lost): a range that does not hold values on both sides of 0, or higher_is_better, is refused."""
    with pytest.raises(ValueError) as caught:
        _signed(value_range, higher_is_better)
    assert str(caught.value) == ("metric 'x': a signed metric is best at 0 (not higher_is_better) and its "
                                 f"value_range holds values on both sides of 0, got {value_range}")


def test_a_fresh_metric_registry_is_a_registry_of_metrics_of_its_own_group():
    """MetricRegistry.__init__ mutants: its kind (``metric`` in every message), its type (a non-Metric refused), its
    group (kept), lfbench's own entry point only for lfbench's group (the built-in metrics first, ``hci``), its
    families (none yet, a list) and no refusal: a metric registers, an unknown id is None then a SpecError."""
    from lfbench.scoring.base import BUILTIN_METRICS, METRICS_GROUP, MetricRegistry
    from lfbench.utils.errors import SpecError

    reg = MetricRegistry("lfbench_test_nothing_installed.metrics")
    assert reg.group == "lfbench_test_nothing_installed.metrics" and reg.entry_points() == []
    assert reg.find("absent") is None and reg.family_patterns == []
    with pytest.raises(SpecError, match=r"^Unknown metric 'absent'\. Available: none$"):
        reg.get("absent")
    with pytest.raises(TypeError, match=r"registered as metric 'fake' is not a Metric$"):
        reg.register(SimpleNamespace(id="fake"))
    mine = reg.register(_signed((-1.0, 1.0)))
    assert reg.get("x") is mine and reg.names() == ["x"]
    # lfbench's own entry point is declared by the registry itself, not only read from the install's metadata
    # (which may be older than the group: a stale lfbench.egg-info beside the sources)
    assert MetricRegistry(METRICS_GROUP).builtins == {"hci": BUILTIN_METRICS} and reg.builtins == {}
    own = MetricRegistry(METRICS_GROUP).entry_points()[0]
    assert (own.name, own.value, own.group) == ("hci", BUILTIN_METRICS, METRICS_GROUP)
    assert MetricRegistry().entry_points() == [] and MetricRegistry().group is None and MetricRegistry().builtins == {}
