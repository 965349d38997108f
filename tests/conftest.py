"""Shared fixtures. Real-data tests read LFBENCH_HCI_ROOT (the HCI data root, e.g. ../shared/data/hci)
and skip cleanly when it is unset; the folder beside it (its parent) holds published/, reference/
and paper/ when present. Every test that uses the ``hci_root`` fixture (directly or through another
fixture) carries the ``realdata`` marker, so ``-m "not realdata"`` runs without the data; so does every test
that uses ``urbanlf_root`` (the released UrbanLF-Syn, LFBENCH_URBANLF_ROOT, not available here). Every test
that uses the ``slurm_cluster`` fixture (a single-node SLURM cluster, tests/slurm_cluster.py) carries the
``slurm`` marker: ``pytest -m slurm`` runs just them."""

from __future__ import annotations

import os
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
