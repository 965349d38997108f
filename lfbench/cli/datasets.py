"""List the dataset adapters (built-in and plugins of the entry-point group ``lfbench.datasets``) with their
layout and scoring protocol, and the plugins that failed to load. ``lfbench evaluate --data ROOT`` detects
which one a root is laid out as; ``--dataset NAME`` forces one."""

from __future__ import annotations

import argparse

HELP = "list the dataset adapters, their layouts and scoring protocols"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--names", action="store_true", help="names only, one per line")


def run(args: argparse.Namespace) -> int:
    from lfbench.data.dataset import DATASETS

    for name in DATASETS.names():
        dataset = DATASETS.get(name)
        if args.names:
            print(name)
            continue
        print(f"{name}: {dataset.summary}")
        print(f"  layout: {dataset.layout}")
        if dataset.protocol_from_data():
            print("  protocol: declared by the data; when it does not say:")
        for line in dataset.protocol.describe():
            print(f"  {line}")
    for name, error in sorted(DATASETS.load_errors.items()):
        print(f"{name}: plugin failed to load: {error}")
    return 0
