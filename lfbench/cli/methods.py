"""List the registered methods (built-in and plugins; a registered network is a method of its own name) with
their parameters, a network's own with them, and the plugins that failed to load."""

from __future__ import annotations

import argparse

HELP = "list the registered methods and their parameters"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--names", action="store_true", help="names only, one per line")


def run(args: argparse.Namespace) -> int:
    from lfbench.method.registry import REGISTRY, list_methods

    for info in list_methods():
        print(info.name if args.names else info.describe())
    for name, error in sorted(REGISTRY.load_errors.items()):
        print(f"{name}: plugin failed to load: {error}")
    return 0
