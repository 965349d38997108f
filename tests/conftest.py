"""Shared fixtures. Real-data tests read LFBENCH_HCI_ROOT (the HCI data root, e.g. ../shared/data/hci)
and skip cleanly when it is unset; the folder beside it (its parent) holds published/, reference/
and paper/ when present. Every test that uses the ``hci_root`` fixture (directly or through another
fixture) carries the ``realdata`` marker, so ``-m "not realdata"`` runs without the data; so does every test
that uses ``urbanlf_root`` (the released UrbanLF-Syn, LFBENCH_URBANLF_ROOT, not available here). Every test
that uses the ``slurm_cluster`` fixture (a single-node SLURM cluster, tests/slurm_cluster.py) carries the
``slurm`` marker: ``pytest -m slurm`` runs just them.

Tests over ~10 CPU s carry the ``slow`` marker and are left out of the default run (pyproject's addopts); CI runs
them as its second step (``pytest -q -m slow``; tests/README.md). Every run ends with the tests that took more
than that without the marker, and ``--cpu-times FILE`` writes every test's CPU and wall seconds as JSON."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
from slurm_cluster import ClusterUnavailable, running_cluster


def _hci_root() -> Path | None:
    value = os.environ.get("LFBENCH_HCI_ROOT")
    return Path(value) if value and Path(value).is_dir() else None


def pytest_sessionstart(session) -> None:
    """Load every plugin installed in this environment into the process-wide registries before any test
    puts a plugin of its own on sys.path (helpers.isolate_registries copies them as they are then)."""
    from lfbench.method.registry import REGISTRY
    from lfbench.method.trainable import TRAINABLES

    REGISTRY.names()
    TRAINABLES.names()


#: A test over this many CPU seconds (setup, call and teardown; its own and its finished child processes') belongs
#: in the slow run (@pytest.mark.slow).
SLOW_CPU_S = 10.0
_TIMES = pytest.StashKey[dict]()


def pytest_addoption(parser) -> None:
    parser.addoption("--cpu-times", metavar="FILE", default=None,
                     help="write each test's CPU seconds (user + system of pytest and of the child processes it "
                          "waited for, setup to teardown), wall seconds and slow mark to FILE (JSON)")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Time each test in CPU seconds (os.times: this process and its finished children) and wall seconds. A session
    or module fixture's setup counts for the first test that uses it."""
    before, start = os.times(), time.perf_counter()
    yield
    after = os.times()
    cpu = sum(after[k] - before[k] for k in range(4))  # user, system, children's user, children's system
    item.config.stash.setdefault(_TIMES, {})[item.nodeid] = {
        "cpu_s": round(cpu, 3), "wall_s": round(time.perf_counter() - start, 3),
        "slow": item.get_closest_marker("slow") is not None}


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    times = config.stash.get(_TIMES, {})
    path = config.getoption("--cpu-times")
    if path:
        Path(path).write_text(json.dumps(dict(sorted(times.items(), key=lambda kv: -kv[1]["cpu_s"])), indent=1) + "\n")
    unmarked = sorted(((t["cpu_s"], nodeid) for nodeid, t in times.items()
                       if t["cpu_s"] > SLOW_CPU_S and not t["slow"]), reverse=True)
    if unmarked:
        terminalreporter.write_sep("-", f"over {SLOW_CPU_S:.0f} CPU s without @pytest.mark.slow (tests/README.md)")
        for cpu, nodeid in unmarked:
            terminalreporter.write_line(f"{cpu:8.1f} CPU s  {nodeid}")


def pytest_collection_modifyitems(config, items) -> None:
    for item in items:
        if {"hci_root", "urbanlf_root"} & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.realdata)
        if "slurm_cluster" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.slurm)


@pytest.fixture(scope="session")
def hci_root() -> Path:
    """The HCI data root (ROOT/<category>/<scene>); skips the test when LFBENCH_HCI_ROOT is unset."""
    root = _hci_root()
    if root is None:
        pytest.skip("LFBENCH_HCI_ROOT is not set (real HCI data not available)")
    return root


@pytest.fixture(scope="session")
def urbanlf_root() -> Path:
    """The released UrbanLF-Syn root (ROOT/{train,val,test}/ImageN); skips the test when LFBENCH_URBANLF_ROOT is
    unset (it is not on this project's machines: the tests that use it are for whoever has the data)."""
    value = os.environ.get("LFBENCH_URBANLF_ROOT")
    if not value or not Path(value).is_dir():
        pytest.skip("LFBENCH_URBANLF_ROOT is not set (the released UrbanLF-Syn is not available)")
    return Path(value)


@pytest.fixture(scope="session")
def slurm_cluster(tmp_path_factory):
    """A running single-node SLURM cluster (munged, slurmctld, slurmd of this host; tests/slurm_cluster.py),
    started once per session and stopped at its end. Skips with the reason where it cannot run (not
    installed, daemons refused by the container); fails instead when LFBENCH_REQUIRE_SLURM=1 (CI sets it after
    installing slurm-wlm and munge)."""
    root = tmp_path_factory.mktemp("slurm")
    try:
        with running_cluster(root) as cluster:
            yield cluster
    except ClusterUnavailable as exc:
        if os.environ.get("LFBENCH_REQUIRE_SLURM") == "1":
            pytest.fail(f"LFBENCH_REQUIRE_SLURM=1 but the SLURM test cluster did not start: {exc}")
        pytest.skip(f"no SLURM test cluster: {exc}")


@pytest.fixture(scope="session")
def example_plugin(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """examples/tiny_plugin installed once per session the way a user installs it (helpers.install_example_plugin):
    (its site folder, an environment whose PYTHONPATH holds it, one OpenMP thread). Shared: never write into the
    site; a test that changes the example's files works on a copy of its own (helpers.example_copy)."""
    from helpers import install_example_plugin

    _, site, env = install_example_plugin(tmp_path_factory.mktemp("example_plugin"))
    return site, env


@pytest.fixture(scope="session")
def shared_data(hci_root: Path) -> Path:
    """The shared data folder beside the HCI root (published/, reference/, paper/)."""
    return hci_root.parent


def require(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} not available")
    return path


@pytest.fixture()
def one_torch_thread():
    """Run a test with one torch thread: tiny tensors avoid OpenMP barrier stalls on a shared, loaded machine."""
    from lfbench.utils.threads import torch_threads

    with torch_threads(1):
        yield


@pytest.fixture()
def cpu_bf16():
    """Skip the test, with the reason, on a CPU that cannot run bf16 convolutions (e.g. AVX2 only)."""
    from lfbench.utils.hardware import cpu_bf16_missing

    missing = cpu_bf16_missing()
    if missing is not None:
        pytest.skip(f"this CPU cannot run bf16 convolutions: it lacks {missing}")
