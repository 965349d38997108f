"""Mutants that the first full mutation run (results/mutation/full_run) counted as timeouts: its forked children hung
on torch's OpenMP pool and ran out their time whatever the mutant did. Run again single-threaded
(results/mutation/full_run/second_pass), most survived. These tests kill them:
- UrbanLF-Syn's scene writer (its refusal of a grid that is not 9x9, its folders, the depth file) and `npy_bytes`'s
  float32;
- `_present`'s chunks;
- `read_head`'s read error and default wording.

Each test names the mutants it kills; the equivalent ones have their reasons in tools/mutation/classify.py.
In-process, small arrays, no CLI.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from lfbench.data.urbanlf import UrbanLFSyn, npy_bytes
from lfbench.scoring.region_metrics import _present
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.readfile import read_head


def _scene(angular: int = 9, *, views: bool = True, depth: bool = True) -> SimpleNamespace:
    rng = np.random.default_rng(angular)
    return SimpleNamespace(
        views=rng.random((angular, angular, 4, 5, 3)) if views else None,
        disparity=rng.uniform(-1, 1, (4, 5)),  # float64: written as float32
        depth=rng.uniform(1, 2, (4, 5)) if depth else None)


@pytest.mark.parametrize(("scene", "shape"), [(_scene(7), "(7, 7)"), (_scene(views=False), "None")])
def test_urbanlf_writes_only_a_9x9_grid_and_says_what_it_got(tmp_path, scene, shape):
    """UrbanLFSyn.write_scene mutants 1 (`and`: a missing grid passes, or raises AttributeError), 6-11 (the shape it
    got lost or sliced otherwise) and 12 (the message lost): one line with the grid it got; nothing is written."""
    with pytest.raises(SpecError) as caught:
        UrbanLFSyn.write_scene(tmp_path / "Image1", scene)
    assert str(caught.value) == f"the UrbanLF-Syn layout has 9x9 views, got {shape}"
    assert not (tmp_path / "Image1").exists()


@pytest.mark.parametrize("with_depth", [True, False])
def test_urbanlf_writes_its_sample_folder_with_parents_and_depth_when_there_is_one(tmp_path, with_depth):
    """UrbanLFSyn.write_scene mutants 15, 17 and 19 (the sample folder's parents not made: split/ImageN under a new
    root) and 45 and 51 (the depth file written when there is none, or of None): the views, the float32 disparity
    and, only with a depth, the float32 depth."""
    scene = _scene(depth=with_depth)
    folder = UrbanLFSyn.write_scene(tmp_path / "root" / "train" / "Image1", scene)
    assert folder == tmp_path / "root" / "train" / "Image1"
    names = sorted(p.name for p in folder.iterdir())
    views = sorted(f"{u}_{v}.png" for u in range(1, 10) for v in range(1, 10))
    assert names == sorted([*views, "5_5_disparity.npy", *(["5_5_depth.npy"] if with_depth else [])])
    disparity = np.load(folder / "5_5_disparity.npy")
    assert disparity.dtype == np.float32 and np.array_equal(disparity, scene.disparity.astype(np.float32))
    if with_depth:
        depth = np.load(folder / "5_5_depth.npy")
        assert depth.dtype == np.float32 and np.array_equal(depth, scene.depth.astype(np.float32))


@pytest.mark.parametrize("dtype", [np.float64, np.int16, np.float16])
def test_npy_bytes_is_a_float32_npy_file(dtype):
    """npy_bytes mutants 9 and 11 (the array saved in its own dtype): the bytes are a float32 .npy of the values."""
    array = np.arange(6, dtype=dtype).reshape(2, 3)[:, ::2]  # not contiguous either
    loaded = np.load(io.BytesIO(npy_bytes(array)), allow_pickle=False)
    assert loaded.dtype == np.float32 and np.array_equal(loaded, array.astype(np.float32))


@pytest.mark.parametrize("chunk", [1, 2, 3, 1 << 20])
def test_present_reads_every_chunk(chunk):
    """_present mutant 21 (`range(0, chunk)`: only the first chunk's starts): labels met after the first chunk are
    present, in the few-labels branch (bits) as in the counting one."""
    few = np.array([0, 0, 0, 0, 5, 0, 0, 7], np.uint8)
    assert np.flatnonzero(_present(few, chunk)).tolist() == [0, 5, 7]
    many = np.array([0, 0, 0, 0, 40, 0, 0, 70], np.int64)  # more values than the bits hold: counted
    assert np.flatnonzero(_present(many, chunk)).tolist() == [0, 40, 70]


def test_a_read_error_in_a_header_is_one_line_naming_the_file():
    """read_head mutants 16-20 (the error's message, its path, its errno text lost): a file that opens but cannot be
    read (/proc/self/mem at offset 0: EIO) is one line with the file, what it is and the system's reason."""
    if not os.path.exists("/proc/self/mem"):
        pytest.skip("needs /proc/self/mem (Linux) for a file that opens but cannot be read")
    with pytest.raises(DataError) as caught:
        read_head("/proc/self/mem", 8, "the view's header")
    assert str(caught.value) == "/proc/self/mem: cannot read the view's header: Input/output error"
    assert caught.value.path == Path("/proc/self/mem")


def test_read_head_calls_what_it_reads_a_file_by_default(tmp_path):
    """read_head mutants 1 and 2 (its default ``what``): a missing file read without a ``what`` is "file"."""
    with pytest.raises(DataError) as caught:
        read_head(tmp_path / "absent.png", 8)
    assert str(caught.value) == f"{tmp_path / 'absent.png'}: file not found"


def _protocol(angular_size):
    from lfbench.data.dataset import DatasetProtocol

    return DatasetProtocol(border_px=2, metrics=("mse_x100",), disparity_range=(-1.0, 1.0), angular_size=angular_size)


def test_a_scene_of_another_angular_size_than_its_protocols_is_refused_naming_both(tmp_path):
    """DatasetProtocol.check_angular_size mutants 1 (the check made only where the protocol fixes no size) and 5-10
    (the message or the scene's path lost): the first scene whose views are not the protocol's size is one line with
    its name, both sizes (u x v) and its path; a protocol without a size takes any."""
    fits = SimpleNamespace(name="a", angular_size=(9, 9), path=tmp_path / "a")
    other = SimpleNamespace(name="b", angular_size=(7, 5), path=tmp_path / "b")
    _protocol((9, 9)).check_angular_size([fits])
    _protocol(None).check_angular_size([fits, other])
    with pytest.raises(DataError) as caught:
        _protocol((9, 9)).check_angular_size([fits, other, fits])
    assert str(caught.value) == (f"{tmp_path / 'b'}: scene 'b' has 5x7 views, its dataset's protocol 9x9: it cannot be "
                                 "scored by that protocol")
    assert caught.value.path == tmp_path / "b"


def test_the_border_is_checked_on_every_scene_after_an_object_that_is_not_one(tmp_path):
    """ScoringRules.check_border mutant 2 (`break` at the first object that is not a Scene): what follows it is
    checked too."""
    from helpers import write_scene

    from lfbench.data.hci import HCIScene
    from lfbench.scoring.rules import ScoringRules

    scene = HCIScene(write_scene(tmp_path, "toy", size=12, views=False))
    ScoringRules(border_px=5).check_border([SimpleNamespace(name="crop"), scene])
    with pytest.raises(DataError) as caught:
        ScoringRules(border_px=6).check_border([SimpleNamespace(name="crop"), scene])
    assert str(caught.value) == (f"{scene.path}: the scoring border of 6 px (the dataset's protocol) leaves no pixel "
                                 "of this scene's 12x12 px views to score")
