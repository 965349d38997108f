"""Describe one method: summary, parameters with types and defaults, and method-specific facts
(e.g. ``trainable_parameters: N`` for networks). Accepts a spec to describe a configured variant."""

from __future__ import annotations

import argparse

HELP = "describe one method (accepts a spec: NAME[:key=value,...])"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", metavar="NAME", help="method name or spec")


def run(args: argparse.Namespace) -> int:
    import inspect

    from lfbench.method.base import overrides
    from lfbench.method.registry import REGISTRY, create_from_spec, parse_spec

    name, raw = parse_spec(args.spec)
    info = REGISTRY.info(name)
    print(info.describe())
    if info.doc and "\n" in info.doc:
        print("\n" + info.doc.split("\n", 1)[1].strip())
    if inspect.isclass(info.factory) and overrides(info.factory, "describe_variant"):
        method = create_from_spec(args.spec) if raw else REGISTRY.create(name)
        for key, value in method.describe_variant().items():
            print(f"{key}: {value}")
    return 0
