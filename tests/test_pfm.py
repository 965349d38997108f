"""PFM read/write: exact round trip, Pf and PF, both byte orders, bottom-up rows, malformed files."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from helpers import pfm_bytes

from lfbench.data.pfm import parse_pfm, read_pfm, write_pfm
from lfbench.utils.errors import DataError


def _special_values(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    arr = rng.standard_normal(shape).astype(np.float32) * np.float32(3.0)
    flat = arr.reshape(-1)
    special = [np.nan, np.inf, -np.inf, -0.0, np.finfo(np.float32).tiny, np.finfo(np.float32).max]
    flat[:len(special)] = special[:flat.size]
    rng.shuffle(flat)
    return arr


@pytest.mark.parametrize("shape", [(7, 5), (1, 1), (1, 9), (6, 4, 3)])
def test_round_trip_is_bit_exact(tmp_path, shape):
    arr = _special_values(np.random.default_rng(0), shape)
    write_pfm(tmp_path / "a.pfm", arr)
    back = read_pfm(tmp_path / "a.pfm")
    assert back.dtype == np.float32 and back.shape == shape
    # bit-level equality: NaN payloads, -0.0 and infinities survive
    assert np.array_equal(back.view(np.uint32), arr.view(np.uint32))


def test_written_file_layout_is_little_endian_bottom_up(tmp_path):
    arr = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], dtype=np.float32)  # 3 wide, 2 high
    write_pfm(tmp_path / "a.pfm", arr)
    raw = (tmp_path / "a.pfm").read_bytes()
    header, payload = raw[:raw.index(b"-1.0\n") + 5], raw[raw.index(b"-1.0\n") + 5:]
    assert header.split(b"\n")[:2] == [b"Pf", b"3 2"]
    # first stored row is the bottom image row (4, 5, 6), little endian
    assert struct.unpack("<6f", payload) == (4.0, 5.0, 6.0, 1.0, 2.0, 3.0)


def test_hand_written_bottom_up_file_reads_top_down(tmp_path):
    # 2 wide, 3 high; rows stored bottom-up: (5, 6), (3, 4), (1, 2)
    raw = b"Pf\n2 3\n-1\n" + struct.pack("<6f", 5, 6, 3, 4, 1, 2)
    (tmp_path / "h.pfm").write_bytes(raw)
    assert read_pfm(tmp_path / "h.pfm").tolist() == [[1, 2], [3, 4], [5, 6]]


@pytest.mark.parametrize("big_endian", [False, True])
@pytest.mark.parametrize("ident", [b"Pf", b"PF"])
def test_both_byte_orders_and_channel_counts(tmp_path, big_endian, ident):
    rng = np.random.default_rng(1)
    shape = (5, 4) if ident == b"Pf" else (5, 4, 3)
    arr = _special_values(rng, shape)
    (tmp_path / "x.pfm").write_bytes(pfm_bytes(arr, ident=ident, big_endian=big_endian))
    back = read_pfm(tmp_path / "x.pfm")
    assert back.shape == shape and back.dtype == np.float32
    assert back.dtype.byteorder in ("=", "<", "|")  # native float32, whatever the file's order
    assert np.array_equal(back.view(np.uint32), arr.view(np.uint32))


def test_big_endian_bytes_by_hand(tmp_path):
    raw = b"Pf\n2 1\n1.0\n" + struct.pack(">2f", 0.5, -2.25)
    (tmp_path / "be.pfm").write_bytes(raw)
    assert read_pfm(tmp_path / "be.pfm").tolist() == [[0.5, -2.25]]


def test_scale_magnitude_multiplies_values_like_the_toolkit(tmp_path):
    raw = b"Pf\n2 1\n-4.0\n" + struct.pack("<2f", 0.5, -2.0)
    (tmp_path / "s.pfm").write_bytes(raw)
    assert read_pfm(tmp_path / "s.pfm").tolist() == [[2.0, -8.0]]


def test_comment_lines_in_header_are_skipped(tmp_path):
    raw = b"Pf\n# made by hand\n1 1\n-1\n" + struct.pack("<f", 7.0)
    (tmp_path / "c.pfm").write_bytes(raw)
    assert read_pfm(tmp_path / "c.pfm").tolist() == [[7.0]]


def test_parse_pfm_from_memory_matches_file(tmp_path):
    arr = _special_values(np.random.default_rng(2), (3, 8))
    data = pfm_bytes(arr)
    assert np.array_equal(parse_pfm(data).view(np.uint32), arr.view(np.uint32))


@pytest.mark.parametrize("raw, fragment", [
    (b"", "header ends early"),
    (b"P6\n2 2\n255\n" + b"\0" * 12, "not a PFM file"),
    (b"\x89PNG\r\n\x1a\n....", "not"),
    (b"Pf\n2 x\n-1\n" + b"\0" * 16, "bad PFM dimensions"),
    (b"Pf\n-2 2\n-1\n" + b"\0" * 16, "bad PFM dimensions"),
    (b"Pf\n2 2\n0\n" + b"\0" * 16, "bad PFM scale"),
    (b"Pf\n2 2\nnan\n" + b"\0" * 16, "bad PFM scale"),
    (b"Pf\n2 2\n-1\n" + b"\0" * 15, "truncated"),
    (b"Pf\n2 2\n-1\n" + b"\0" * 17, "trailing bytes"),
    (b"Pf\n100000 100000\n-1\n" + b"\0" * 16, "more than lfbench reads"),  # absurd size: no huge allocation
    (b"Pf\n3000 3000\n-1\n" + b"\0" * 16, "truncated"),
    (b"Pf\n99999999999 99999999999\n-1\n" + b"\0" * 16, "more than lfbench reads"),
])
def test_malformed_files_raise_one_line_data_error_naming_the_file(tmp_path, raw, fragment):
    path = tmp_path / "bad.pfm"
    path.write_bytes(raw)
    with pytest.raises(DataError) as info:
        read_pfm(path)
    msg = str(info.value)
    assert fragment in msg and str(path) in msg and "\n" not in msg


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(DataError, match="file not found"):
        read_pfm(tmp_path / "nope.pfm")
    with pytest.raises(DataError, match="is a folder"):
        read_pfm(tmp_path)


def test_write_refuses_bad_shapes_and_leaves_nothing(tmp_path):
    with pytest.raises(ValueError):
        write_pfm(tmp_path / "bad.pfm", np.zeros((2, 2, 2), dtype=np.float32))
    with pytest.raises(ValueError):
        write_pfm(tmp_path / "bad.pfm", np.zeros(5, dtype=np.float32))
    assert list(tmp_path.iterdir()) == []


def test_real_ground_truth_reads(hci_root):
    for path in sorted(hci_root.glob("*/*/gt_disp_lowres.pfm")):
        gt = read_pfm(path)
        assert gt.shape == (512, 512) and gt.dtype == np.float32
        assert np.isfinite(gt).all()
        assert -4.0 < float(gt.min()) < float(gt.max()) < 4.0  # disparities of the HCI scenes are within +-4 px
        # the file is Pf, little endian, 512x512: 4 bytes per pixel after the header
        raw = path.read_bytes()
        assert raw.startswith(b"Pf\n512 512\n-") and len(raw) - raw.index(b"\n", 11) - 1 == 512 * 512 * 4
