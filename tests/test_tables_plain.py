"""Table I and II without pandas (lfbench.reports.tables.Table) against pandas itself: the same numbers, the same
DataFrame, the same files.

The reference is ``DataFrame.pivot_table`` as the tables were built before (kept below, written from pandas'
API): Table I takes the first non-NaN value of each (scene, metric, method) and drops a row of NaN only; Table II
is pandas' groupby mean (a Kahan-compensated sum), so every value must be equal bit for bit, on results with NaN,
infinities, duplicates, methods on different scenes and values of very different magnitudes."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pandas.core.groupby.ops as pandas_ops
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lfbench.reports.tables import (
    Table,
    average_rows,
    average_table,
    group_mean,
    group_means,
    per_scene_rows,
    per_scene_table,
    render,
)
from lfbench.results import Record, Results, RunInfo
from lfbench.scoring.metrics import metric_order

# --------------------------------------------------------------------------- pandas' tables, as they were built

def pandas_per_scene(results: Results, metrics=None) -> pd.DataFrame:
    df = results.to_frame()
    order = metric_order(metrics or list(dict.fromkeys(df["metric"])))
    df = df[df["metric"].isin(order)]
    table = df.pivot_table(index=["scene", "metric"], columns="method", values="value", aggfunc="first", sort=False)
    res = df.groupby(["scene", "metric"], sort=False)["resolution"].agg(lambda s: "/".join(sorted(set(s))))
    table = table.reindex(columns=list(dict.fromkeys(df["method"])))
    table.insert(0, "resolution", res)
    scenes = list(dict.fromkeys(df["scene"]))
    idx = [(s, m) for s in scenes for m in order if (s, m) in table.index]
    return table.loc[idx]


def pandas_average(results: Results, metrics=None) -> pd.DataFrame:
    df = results.to_frame()
    order = metric_order(metrics or list(dict.fromkeys(df["metric"])))
    table = (df[df["metric"].isin(order)]
             .pivot_table(index="method", columns="metric", values="value", aggfunc="mean", sort=False))
    table = table.reindex(index=list(dict.fromkeys(df["method"])), columns=order)
    table["scenes"] = df.groupby("method", sort=False)["scene"].nunique()
    if results.runs:
        rt = pd.DataFrame([(r.method, r.runtime_s) for r in results.runs], columns=["method", "runtime_s"])
        table["runtime_s"] = rt.groupby("method")["runtime_s"].mean()
    return table


# --------------------------------------------------------------------------- random results

#: pandas from 3.1 sums contiguous groups without NaN by numpy.add.reduceat (what lfbench's tables follow); an
#: earlier pandas sums every group with its Kahan kernel: another reference, to the last bit
pytestmark = [pytest.mark.skipif(not hasattr(pandas_ops, "_REDUCEAT_UFUNCS"),
                                 reason="the reference is pandas 3.1's groupby (reduceat of contiguous groups)"),
              pytest.mark.filterwarnings("ignore:invalid value encountered in reduceat:RuntimeWarning")]

VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.floats(min_value=-1e3, max_value=1e3, allow_nan=False),
    st.sampled_from([0.0, -0.0, 0.1, 0.2, 0.3, 1e16, -1e16, 1.0, 3.0, float("nan"), float("inf"), -float("inf")]),
)
NAMES = {"method": ["subfocal", "planesweep", "a|b", "x,y"], "scene": ["backgammon", "dots", "s\"1", "boxes"],
         "metric": ["badpix_0.07", "mse_x100", "q25_x100", "bumpiness_planes", "my_metric", "badpix_0.01"]}


@st.composite
def results_strategy(draw) -> Results:
    n = draw(st.integers(1, 40))
    resolutions = st.sampled_from(["lowres", "highres"])
    records = [Record(draw(st.sampled_from(NAMES["method"])), draw(st.sampled_from(NAMES["scene"])),
                      draw(st.sampled_from(NAMES["metric"])), draw(VALUES), draw(resolutions)) for _ in range(n)]
    if draw(st.booleans()):  # each (method, metric) contiguous: pandas sums them by numpy.add.reduceat
        records.sort(key=lambda r: (r.method, r.metric))
    methods = list(dict.fromkeys(r.method for r in records))
    runs = [RunInfo(draw(st.sampled_from(methods)), draw(st.sampled_from(NAMES["scene"])), draw(VALUES))
            for _ in range(draw(st.integers(0, 12)))]
    if draw(st.booleans()):
        runs.sort(key=lambda r: r.method)
    return Results(records=records, runs=runs)


def _same_frame(ours: pd.DataFrame, theirs: pd.DataFrame) -> None:
    pd.testing.assert_frame_equal(ours, theirs, check_exact=True)
    for column in ours.columns:  # bit for bit, signed zeros and the NaN places included
        if ours[column].dtype.kind == "f":
            assert np.array_equal(ours[column].to_numpy().view(np.int64) >> 63,
                                  theirs[column].to_numpy().view(np.int64) >> 63) or ours[column].isna().any()


SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize("rows, frame, reference", [(per_scene_rows, per_scene_table, pandas_per_scene),
                                                    (average_rows, average_table, pandas_average)],
                         ids=["table1", "table2"])
@SETTINGS
@given(results=results_strategy())
def test_tables_are_pandas_tables(rows, frame, reference, results):
    """Table I: the first non-NaN value per cell, rows of NaN only dropped, resolutions joined, pandas' order;
    Table II: pandas' groupby mean of the non-NaN values, the scene count, the mean runtime. The DataFrame and
    every format written, character for character."""
    theirs = reference(results)
    _same_frame(frame(results), theirs)
    table = rows(results)
    for fmt in ("markdown", "latex", "csv", "plain"):
        assert render(table, fmt) == render(theirs, fmt)


@SETTINGS
@given(results_strategy(), st.lists(st.sampled_from(NAMES["metric"] + ["absent"]), min_size=1, max_size=3, unique=True))
def test_tables_of_chosen_metrics(results, metrics):
    """Only the metrics asked for, in the tables' order; a method without them keeps its Table II row."""
    if not set(metrics) & set(results.metrics):
        return  # pandas' pivot of no row is not a table
    _same_frame(per_scene_table(results, metrics), pandas_per_scene(results, metrics))
    _same_frame(average_table(results, metrics), pandas_average(results, metrics))


def _bits(x: float) -> bytes:
    return b"nan" if math.isnan(x) else np.float64(x).tobytes()


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.sampled_from("abc"), VALUES), min_size=1, max_size=40), st.booleans(), st.booleans())
def test_group_means_are_pandas_groupby_mean(pairs, contiguous, sort):
    """pandas' groupby mean bit for bit, on both of pandas 3.1's paths: contiguous groups without NaN (a numpy
    reduceat sum, pairwise from 8 values), anything else (the Kahan kernel: NaN left out, an infinity not turned
    into NaN by the compensation); groups in first-appearance or sorted order."""
    if contiguous:
        pairs = sorted(pairs, key=lambda p: p[0])
    keys, values = [k for k, _ in pairs], [v for _, v in pairs]
    theirs = pd.Series(values, dtype=np.float64).groupby(pd.Series(keys, dtype=object), sort=sort).mean()
    ours = group_means(keys, values, sort=sort)
    assert list(ours) == list(dict.fromkeys(keys))
    assert {k: _bits(v) for k, v in ours.items()} == {k: _bits(float(theirs[k])) for k in ours}


def test_group_mean_by_hand():
    """Values written out: the compensated sum of 0.1, 0.2 and 0.3 is 0.6 (a plain float sum gives
    0.6000000000000001), NaN is skipped, +inf and -inf give NaN, one infinity stays infinite."""
    assert group_mean([0.1, 0.2, 0.3]) == 0.6 / 3
    assert (0.1 + 0.2 + 0.3) / 3 != 0.6 / 3
    assert group_mean([1.0, float("nan"), 3.0]) == 2.0
    assert math.isnan(group_mean([float("inf"), -float("inf")]))
    assert group_mean([float("inf"), 1.0]) == float("inf")
    assert math.isnan(group_mean([float("nan")]))


def test_table_csv_quotes_and_empty_fields():
    """CSV as pandas writes it: a field with a comma or a quote quoted, NaN an empty field, ints as ints."""
    table = Table(index=("method",), columns=("v", "scenes"), rows=(('a,"b"', float("nan"), 3), ("c", 0.1234567, 1)),
                  ints=frozenset({"scenes"}))
    assert table.to_csv() == 'method,v,scenes\n"a,""b""",,3\nc,0.123457,1\n'
    assert table.to_csv() == table.to_frame().reset_index().to_csv(index=False, float_format="%.6g")
