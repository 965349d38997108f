"""Issue 38, one executor for every pool: lfbench.utils.executor.ProcessPool runs the ablation's cells,
``evaluate --jobs N``'s scoring and ``synth --workers N``'s scenes. A generator of items is pulled lazily (at most
one ahead of the running jobs); any worker that dies is one line naming its item (here an ablation cell's); the
scoring and synth workers never import torch; UrbanLF-Syn scenes, now written through the adapter's write_scene
and the same pool as HCI's, are what the former writer wrote."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from helpers import write_scene
from PIL import Image

from lfbench.utils.executor import KILL_WORKER_ENV, ClusterOptions, ProcessPool, executor_for

# --------------------------------------------------------------------------- a generator is pulled lazily


@pytest.mark.parametrize("jobs", [1, 2, 3])
def test_a_generator_of_items_is_pulled_at_most_one_ahead_of_the_running_jobs(jobs):
    pulled = []
    ahead = []  # at each result: items pulled but not yet done
    results = []

    def items():
        for k in range(12):
            pulled.append(k)
            yield k

    def done(result):
        ahead.append(len(pulled) - len(results))
        results.append(result)

    pool = executor_for(ClusterOptions("pool"), jobs=jobs)
    pool.map(abs, (-k for k in items()), labels=str, threads=None, on_done=done, cost=float)
    assert sorted(results) == list(range(12))
    assert len(pulled) == 12
    assert max(ahead) <= jobs + 1, ahead  # never the whole generator at once
    assert ahead[0] == (jobs + 1 if jobs > 1 else 1)  # workers: the running ones and the next one made
    if jobs == 1:
        assert results == list(range(12))  # in this process, in order


def test_a_sequence_keeps_its_labels_and_runs_the_costliest_first():
    pool = ProcessPool(ClusterOptions("pool"), jobs=1)
    started = []
    out = []
    pool.map(abs, [-1, -2], labels=["one", "two"], threads=None, on_done=out.append, on_start=started.append)
    assert started == ["one", "two"] and out == [1, 2]
    with pytest.raises(ValueError):  # a label per item
        pool.map(abs, [-1, -2], labels=["one"], threads=None, on_done=out.append)


# --------------------------------------------------------------------------- a dead ablation cell worker

TWO_CELLS = """
title = "two cells"
table = "table4"
[[grid]]
interval = [1.0, 2.0]
"""


@pytest.mark.slow  # ~17 CPU s: the synthetic data, and the other cell's worker importing torch
def test_a_killed_ablation_cell_worker_is_one_line_naming_the_cell(tmp_path):
    """An ablation cell's pool worker SIGKILLed (as the out-of-memory killer would): one line naming the cell,
    exit 1 (the run failed, not its input), no BrokenProcessPool traceback."""
    from test_ablate import write_spec

    from lfbench.ablation.spec import load_spec

    spec = write_spec(tmp_path, TWO_CELLS)
    victim = f"cell {load_spec(spec).cells[1].id}"
    env = {**os.environ, KILL_WORKER_ENV: victim}
    proc = subprocess.run([sys.executable, "-m", "lfbench", "-q", "ablate", str(spec), "--out", str(tmp_path / "out"),
                           "--jobs", "2", "--no-progress"], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "BrokenProcessPool" not in proc.stderr, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if "error" in line]
    assert len(errors) == 1, proc.stderr
    assert errors[0].startswith("lfbench ablate: error: a worker process died (killed, or out of memory) while "
                                f"running {victim!r}"), errors[0]


# --------------------------------------------------------------------------- no torch in scoring / synth workers

PROBE = '''
import os
import sys
from pathlib import Path

from lfbench.data import synth
from lfbench.runs import runner


def _mark(kind):
    folder = Path(os.environ["LFBENCH_TEST_PROBE_DIR"])
    (folder / f"{kind}-{os.getpid()}-{len(list(folder.iterdir()))}").write_text(
        " ".join(m for m in ("torch", "torch.cuda") if m in sys.modules) or "none", encoding="utf-8")


def score_task(task):
    _mark("score")
    return runner.score_task(task)


def write_one(job):
    _mark("synth")
    return synth._write_one(job)
'''


@pytest.fixture()
def probe(tmp_path, monkeypatch):
    """A module the spawned workers import (sys.path and the environment are inherited), whose functions run the
    real work and record which of torch's modules the worker has loaded."""
    (tmp_path / "probe_mod").mkdir()
    (tmp_path / "probe_mod" / "lfbench_torch_probe.py").write_text(textwrap.dedent(PROBE), encoding="utf-8")
    marks = tmp_path / "marks"
    marks.mkdir()
    monkeypatch.syspath_prepend(str(tmp_path / "probe_mod"))
    monkeypatch.setenv("LFBENCH_TEST_PROBE_DIR", str(marks))
    import lfbench_torch_probe

    return lfbench_torch_probe, marks


def test_scoring_workers_do_not_import_torch(tmp_path, monkeypatch, probe):
    from lfbench.data.hci import HCIDataset
    from lfbench.method.registry import create_from_spec
    from lfbench.runs import runner

    module, marks = probe
    for i, name in enumerate(("alpha", "beta", "gamma")):
        write_scene(tmp_path / "data", name, "training", size=32, seed=i)
    scenes = list(HCIDataset.open(tmp_path / "data").scenes)
    one = runner.evaluate([create_from_spec("gt")], scenes, progress=False, jobs=1)
    monkeypatch.setattr(runner, "score_task", module.score_task)
    two = runner.evaluate([create_from_spec("gt")], scenes, progress=False, jobs=2)
    assert [repr((r.method, r.scene, r.metric, r.value)) for r in one.records] == \
        [repr((r.method, r.scene, r.metric, r.value)) for r in two.records]
    seen = sorted(p.name.split("-")[0] for p in marks.iterdir())
    assert seen == ["score"] * 3  # every scene scored in a worker
    assert {p.read_text() for p in marks.iterdir()} == {"none"}


def test_synth_workers_do_not_import_torch(tmp_path, monkeypatch, probe):
    from lfbench.data import synth

    module, marks = probe
    monkeypatch.setattr(synth, "_write_one", module.write_one)
    synth.write_benchmark(tmp_path / "out", seed=1, size=16, scenes=2, angular=3, workers=2)
    assert sorted(p.name.split("-")[0] for p in marks.iterdir()) == ["synth"] * 2
    assert {p.read_text() for p in marks.iterdir()} == {"none"}


# --------------------------------------------------------------------------- UrbanLF-Syn through write_scene


def _content_digest(folder: Path) -> str:
    """sha256 of every file under ``folder`` by relative name: a PNG's decoded pixels (so that another zlib's
    encoding of the same pixels agrees), any other file's bytes."""
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            h.update(p.relative_to(folder).as_posix().encode())
            h.update(np.asarray(Image.open(p)).tobytes() if p.suffix == ".png" else p.read_bytes())
    return h.hexdigest()


#: _content_digest of write_urbanlf(OUT, seed=3, width=24, height=16, scenes=1) written by the code before issue 38
#: moved the writer into UrbanLFSyn.write_scene (commit c4b9f6f), computed with:
#:   mkdir /tmp/old && git archive c4b9f6f lfbench | tar -x -C /tmp/old && PYTHONPATH=/tmp/old python -c \
#:     "from lfbench.data.synth_urbanlf import write_urbanlf; write_urbanlf('/tmp/u', seed=3, width=24, height=16,
#:     scenes=1)"
#:   then _content_digest(Path('/tmp/u')) (this function, pasted into the same interpreter)
OLD_URBANLF_DIGEST = "7cb2d526d313c1f943f1f9c72a967fca0325cdb22c04c8b751b0208594d5f954"


@pytest.mark.parametrize("workers", [1, 2])
def test_synth_urbanlf_through_write_scene_is_what_the_former_writer_wrote(tmp_path, workers):
    from lfbench.data.scene import png_bytes
    from lfbench.data.synth import generate_scene, quantize, scene_seed
    from lfbench.data.synth_urbanlf import write_urbanlf
    from lfbench.data.urbanlf import URBANLF_DISPARITY_RANGE, depth_name, gt_name, npy_bytes, view_name

    out = tmp_path / f"w{workers}"
    (folder,) = write_urbanlf(out, seed=3, width=24, height=16, scenes=1, workers=workers)
    assert _content_digest(out) == OLD_URBANLF_DIGEST
    # an independent reading: the square scene rendered at 24 px, its centre 16 rows, each file's exact bytes
    scene = generate_scene(scene_seed(3, 0), size=24, angular=9, name="Image1", category="val",
                           disparity_range=URBANLF_DISPARITY_RANGE)
    rows = slice(4, 20)
    views = quantize(scene.views[:, :, rows, :])
    expected = {view_name(r + 1, c + 1): png_bytes(views[r, c]) for r in range(9) for c in range(9)}
    expected[gt_name()] = npy_bytes(scene.disparity[rows])
    expected[depth_name()] = npy_bytes(scene.depth[rows])
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == expected
    assert np.asarray(Image.open(folder / "5_5.png")).shape == (16, 24, 3)


def test_the_urbanlf_adapter_writes_a_generated_scene_and_refuses_other_view_grids(tmp_path):
    from lfbench.data.dataset import DATASETS
    from lfbench.data.synth import generate_scene, write_scene
    from lfbench.utils.errors import SpecError

    scene = generate_scene(1, size=16, angular=9).crop(16, 12)
    folder = write_scene(scene, tmp_path / "Image1", "urbanlf-syn")
    opened = DATASETS.get("urbanlf-syn").open(tmp_path)
    assert [s.name for s in opened.scenes] == ["Image1"] and folder == tmp_path / "Image1"
    assert np.array_equal(opened.scenes[0].gt_disparity(), scene.disparity)
    with pytest.raises(SpecError, match="9x9 views"):
        write_scene(generate_scene(1, size=16, angular=3), tmp_path / "Image2", "urbanlf-syn")
