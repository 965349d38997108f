"""Survivors of issue 31's mutation run (results/mutation/issue31/README.md), each a behaviour of the code
issue 31 added that no test pinned: the one check of a prediction (lfbench.data.disparity), the bounded CSV
reader (lfbench.utils.readfile.read_csv) and the gate's NEW records and defaults (lfbench.runs.regress.check).

Expected values are written from each function's docstring, never from its output. The mutants each test
kills are named in its docstring (mutmut's names, lfbench. left out)."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from lfbench.data.disparity import check_disparity, disparity_problem
from lfbench.results import Record, Results
from lfbench.runs.regress import GoldenRecord, check
from lfbench.utils.errors import DataError
from lfbench.utils.readfile import check_regular_file, file_sha256, read_bytes, read_csv, read_text

CROP_NOTE = " (only a symmetric crop of at most the evaluation border can be aligned)"


# --------------------------------------------------------------------------- the one check of a prediction

@pytest.mark.parametrize("shape", [(64, 62), (62, 64)])
def test_a_crop_of_one_axis_only_is_aligned(shape):
    """A symmetric crop of the columns only (or the rows only) is a crop: dh == 0 (dw == 0) is allowed
    (kills data.disparity.x_disparity_problem__mutmut_21..24: `dh >= 0` -> `dh > 0` / `dh >= 1`, same for dw)."""
    assert disparity_problem(True, "float32", shape, (64, 64), max_crop=15) is None
    assert disparity_problem(True, "float32", shape, (64, 64), max_crop=None) is None


def test_the_size_message_says_whether_a_crop_could_be_aligned():
    """Exact text: no note when no crop is accepted, the note when one is (kills x_disparity_problem__mutmut_40..44:
    the note set to None, always or never given, 'XXXX' for the empty note, the condition reversed)."""
    assert disparity_problem(True, "float32", (64, 61), (64, 64)) == "prediction is 61x64, scene is 64x64"
    assert disparity_problem(True, "float32", (64, 61), (64, 64), max_crop=15) == \
        "prediction is 61x64, scene is 64x64" + CROP_NOTE


def test_check_disparity_accepts_no_crop_by_default():
    """``max_crop`` defaults to 0: exactly the light field's size (kills x_check_disparity__mutmut_1: default 1)."""
    with pytest.raises(DataError) as err:
        check_disparity(np.zeros((62, 62), np.float32), (64, 64), "m on s")
    assert str(err.value) == "m on s: prediction is 62x62, scene is 64x64"
    assert check_disparity(np.zeros((62, 62), np.float32), (64, 64), "m on s", max_crop=1).shape == (62, 62)


class _Unconvertible:
    """What a plugin might return: an object numpy cannot turn into an array (a CUDA tensor, say)."""

    def __array__(self, *args, **kwargs):
        raise RuntimeError("cannot convert")


@pytest.mark.parametrize(("value", "kind"), [(_Unconvertible(), "_Unconvertible"),
                                             ([np.zeros(2), np.zeros(3)], "list")])
def test_a_value_numpy_cannot_convert_is_one_line_naming_its_type(value, kind):
    """One DataError naming the returned value's type, never an AttributeError (kills x_check_disparity__mutmut_4:
    `arr = ""` when np.asarray raises, and __mutmut_12: the type of None named instead)."""
    with pytest.raises(DataError) as err:
        check_disparity(value, (4, 4), "m on s")
    assert str(err.value) == f"m on s: disparity must be an array of real floating-point values, got a {kind}"


# --------------------------------------------------------------------------- the bounded CSV reader

def test_read_csv_names_the_table_as_a_csv_table_by_default(tmp_path):
    """``what`` defaults to 'CSV table' and reaches the read (kills utils.readfile.x_read_csv__mutmut_1..3, 6, 9:
    the default changed, None or the byte cap passed as ``what``)."""
    with pytest.raises(DataError) as err:
        read_csv(tmp_path / "absent.csv")
    assert str(err.value) == f"{tmp_path / 'absent.csv'}: CSV table not found"
    with pytest.raises(DataError) as err:
        read_csv(tmp_path / "absent.csv", "ci.csv")
    assert str(err.value) == f"{tmp_path / 'absent.csv'}: ci.csv not found"


def test_read_csv_applies_its_byte_cap(tmp_path):
    """``max_bytes`` reaches the read (kills x_read_csv__mutmut_10: the cap left out, 64 MiB instead)."""
    path = tmp_path / "t.csv"
    path.write_text("a,b\n1,2\n3,4\n")  # 12 bytes
    with pytest.raises(DataError) as err:
        read_csv(path, max_bytes=11)
    assert str(err.value) == f"{path}: CSV table is larger than 11 bytes, more than lfbench reads"
    assert read_csv(path, max_bytes=12).to_dict("list") == {"a": [1, 3], "b": [2, 4]}


def test_an_empty_csv_is_one_line_naming_the_file(tmp_path):
    """An empty file has no widest line (0 fields) and is pandas' EmptyDataError, reported with pandas' first
    line and the file (kills x_read_csv__mutmut_21, 23: max() without its default 0; 38..43: the message or
    the path dropped, None's text, the second line of pandas' one-line message)."""
    path = tmp_path / "empty.csv"
    path.write_text("")
    with pytest.raises(DataError) as err:
        read_csv(path)
    assert str(err.value) == f"{path}: not a readable CSV table: No columns to parse from file"


@pytest.mark.parametrize(("cap", "said"), [(1 << 20, "1 MiB"), (3 << 19, "1.5 MiB"), ((1 << 20) - 1, "1048575 bytes")])
def test_the_byte_cap_is_said_in_mib_from_one_mib_on(tmp_path, cap, said):
    """The cap in a refusal: MiB (as :g writes it) from 1024**2 bytes on, bytes below (kills
    utils.readfile.x__size__mutmut_1..10: the unit, its divisor or its threshold changed)."""
    path = tmp_path / "big.txt"
    path.write_bytes(b"x" * (cap + 1))
    with pytest.raises(DataError) as err:
        read_bytes(path, max_bytes=cap)
    assert str(err.value) == f"{path}: file is larger than {said}, more than lfbench reads"


def test_the_readers_name_a_file_as_file_by_default(tmp_path):
    """``what`` defaults to 'file' and reaches the check (kills x_check_regular_file__mutmut_1, 2, 5 and
    x_read_text__mutmut_1, 2: the default changed or None passed)."""
    missing = tmp_path / "absent.cfg"
    for read in (check_regular_file, read_text, read_bytes, file_sha256):
        with pytest.raises(DataError) as err:
            read(missing)
        assert str(err.value) == f"{missing}: file not found", read.__name__


def test_read_text_decodes_utf8_strictly_unless_told(tmp_path):
    """Bytes that are not UTF-8: one error naming the file by default; ``errors`` reaches the decoding (kills
    x_read_text__mutmut_3, 4: an unknown error handler, a LookupError; 17: ``errors`` left out; 20..22: the
    message or the path dropped)."""
    path = tmp_path / "latin1.cfg"
    path.write_bytes("caf\u00e9\n".encode("latin-1"))
    with pytest.raises(DataError) as err:
        read_text(path)
    assert str(err.value) == f"{path}: file is not UTF-8 text"
    assert read_text(path, errors="replace") == "caf\ufffd\n"


def test_file_sha256_hashes_every_byte_of_a_file_of_several_pieces(tmp_path):
    """The digest (and the bytes) of a file longer than one 1 MiB piece are those of all its bytes (kills
    x_file_sha256 mutants that read one piece only, stop early or hash something else)."""
    import hashlib

    data = np.random.default_rng(1).integers(0, 256, (1 << 20) + 12345, dtype=np.uint8).tobytes()
    path = tmp_path / "w.bin"
    path.write_bytes(data)
    assert file_sha256(path) == hashlib.sha256(data).hexdigest()
    assert read_bytes(path) == data  # the pieces joined as they were read (kills x_read_bytes__mutmut_49)
    assert file_sha256(tmp_path / "w.bin", "weights") == hashlib.sha256(data).hexdigest()
    with pytest.raises(DataError) as err:
        file_sha256(tmp_path, "weights")
    assert str(err.value) == f"{tmp_path}: weights is a folder, expected a file"


@pytest.mark.skipif(not os.path.exists("/proc/self/mem"), reason="needs Linux's /proc/self/mem")
@pytest.mark.parametrize("read", [read_bytes, file_sha256])
def test_a_read_that_fails_is_one_line_naming_the_file(read):
    """/proc/self/mem is a regular file whose read at offset 0 fails (EIO): one error naming the file and the
    system's reason (kills x_read_bytes__mutmut_36..40 and x_file_sha256__mutmut_21..25: the message or the
    path dropped, `strerror and exc`)."""
    with pytest.raises(DataError) as err:
        read("/proc/self/mem", "memory")
    assert str(err.value) == "/proc/self/mem: cannot read memory: Input/output error"


def test_an_open_that_fails_or_a_device_is_one_line_naming_the_file(tmp_path):
    """An open refused for another reason than a missing file (a name too long) and a device: one error naming
    the file, its reason and kind (kills x__open__mutmut_34..38: the message or the path dropped, `strerror and
    exc`; 50, 51: the kind's text)."""
    long_name = tmp_path / ("x" * 300)
    with pytest.raises(DataError) as err:
        read_bytes(long_name)
    assert str(err.value) == f"{long_name}: cannot read file: File name too long"
    if os.path.exists("/dev/null"):
        with pytest.raises(DataError) as err:
            read_bytes("/dev/null")
        assert str(err.value) == "/dev/null: file is not a regular file (a device, FIFO or socket), expected a file"


# --------------------------------------------------------------------------- the gate: NEW records, defaults

def _gate(values: dict[str, float], **options):
    golden = [GoldenRecord("m", "s", "mse_x100", 1.0, 0.0, "lowres")]
    records = [Record("m", "s", "mse_x100", 1.0, "lowres")]
    records += [Record("m", "s", metric, v, "lowres") for metric, v in values.items()]
    return check(golden, Results(records=records), **options)


@pytest.mark.parametrize("value", [0.0, 100.0])
def test_a_new_record_at_an_end_of_its_range_is_a_value(value):
    """badpix ranges over [0, 100] %, both ends included (kills runs.regress.x__out_of_range__mutmut_2, 3:
    `low <= value <= high` -> `<` at either end)."""
    gate = _gate({"badpix_0.07": value})
    assert gate.passed and [(f.kind, f.failed) for f in gate.findings] == [("new", False)]


def test_a_new_record_of_an_unknown_metric_is_reported_not_judged():
    """A NEW record of an id lfbench does not know has no range to check: reported, passes (kills
    x__invalid__mutmut_4: `_out_of_range(None, ...)` called, an AttributeError)."""
    gate = _gate({"someones_metric": 1e9})
    assert gate.passed
    assert [f.message for f in gate.findings] == ["NEW      m/s/someones_metric: 1e+09 is not in the golden file"]


def test_a_new_record_that_cannot_be_a_value_says_why():
    """The NEW line of an invalid value ends with why (kills x_check__mutmut_116: the reason left out)."""
    gate = _gate({"badpix_0.07": math.nan, "mse_x100": 1.0})
    assert [f.message for f in gate.failures] == \
        ["NEW      m/s/badpix_0.07: nan is not in the golden file (INVALID: value is nan)"]


def test_the_gate_skips_nothing_and_passes_nothing_empty_by_default():
    """Defaults: a golden scene absent from the new results is MISSING (not skipped), and comparing nothing
    does not pass (kills x_check__mutmut_1: skip_absent_scenes=True, __mutmut_3: allow_empty=True)."""
    golden = [GoldenRecord("m", "other", "mse_x100", 1.0, 0.0, "lowres")]
    gate = check(golden, Results(records=[Record("m", "s", "mse_x100", 1.0, "lowres")]))
    assert [(f.kind, f.key) for f in gate.failures] == [("missing", ("m", "other", "mse_x100"))]
    assert not check([], Results(records=[])).passed
    assert check([], Results(records=[]), allow_empty=True).passed


# --------------------------------------------------------------------------- pixel-wise families (issue 29)

def test_a_mean_of_one_value_is_that_value_and_of_none_is_nan_silently():
    """MSE's family (Mean, scale 100): one pixel is its own mean; no pixel is NaN with no RuntimeWarning
    (kills scoring.pixelwise.xǁMeanǁreduce__mutmut_7: NaN for size 1, __mutmut_1: np.average of nothing)."""
    import warnings

    from lfbench.scoring.pixelwise import Mean

    assert Mean().reduce(np.array([0.5], np.float32)) == 50.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert math.isnan(Mean().reduce(np.empty(0, np.float32)))


def test_pooled_mean_replicates_are_shifted_onto_the_float32_mean():
    """Every cluster taken once is the sample itself: its replicate is the metric's own value (the float32
    mean x scale), not the float64 mean (kills xǁMeanǁpooled_replicates__mutmut_11: the shift subtracted,
    __mutmut_16: the float64 mean taken in float32, which cancels the shift)."""
    from lfbench.scoring.pixelwise import Mean

    values = (np.random.default_rng(3).random(100_003) ** 3).astype(np.float32)
    family, gid = Mean(), np.arange(values.size) % 7
    own, plain = family.reduce(values), 100.0 * float(values.mean(dtype=np.float64))
    assert abs(own - plain) > 1e-8  # the two means differ in float32's last digits: the shift matters
    reps = family.pooled_replicates(values, gid, np.ones((1, 7)))
    assert reps[0] == pytest.approx(own, rel=1e-12, abs=0)


def test_pooled_replicates_allow_clusters_without_pixels():
    """A cluster with no pixel of the sample (the last tiles fully outside the mask) pools nothing (kills
    x__pooled_means__mutmut_9, 15: bincount without minlength, shorter than the clusters)."""
    from lfbench.scoring.pixelwise import Mean, Proportion

    counts = np.array([[1, 1, 1, 1], [2, 0, 5, 3]])
    gid = np.array([0, 0, 1])
    assert Proportion().pooled_replicates(np.array([True, False, True]), gid, counts).tolist() == [
        pytest.approx(200 / 3), pytest.approx(100.0 * 2 / 4)]
    assert Mean(scale=1.0).pooled_replicates(np.array([1.0, 2.0, 6.0]), gid, counts)[0] == pytest.approx(3.0)


def test_order_statistic_replicates_draw_the_kth_value_of_its_percentage():
    """Q50 of 50 zeros and 50 ones is the value at index int(100 x 50 / 100) = 50; a resample's value there is 1
    when at most 50 of its 100 draws are zeros: P = P(Binomial(100, 1/2) <= 50) = 0.5398 (index 49: 0.4602)
    (kills xǁOrderStatisticǁreplicates__mutmut_12: / 101.0)."""
    import scipy.stats

    from lfbench.scoring.pixelwise import OrderStatistic

    values = np.repeat(np.array([0.0, 1.0], np.float32), 50)
    reps = OrderStatistic(percentage=50.0).replicates(values, 20_000, np.random.default_rng(0))
    assert set(np.unique(reps)) <= {0.0, 1.0}
    assert reps.mean() == pytest.approx(scipy.stats.binom.cdf(50, 100, 0.5), abs=0.02)
