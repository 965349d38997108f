"""Describe one method: summary, parameters with types, defaults and help (a network's too), its
description, and method-specific facts (e.g. ``trainable_parameters: N`` for networks, the weights it
loads). Accepts a spec to describe a configured variant."""

from __future__ import annotations

import argparse

HELP = "describe one method (accepts a spec: NAME[:key=value,...])"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", metavar="NAME", help="method name or spec")


def run(args: argparse.Namespace) -> int:
    from lfbench.method.base import overrides
    from lfbench.method.registry import REGISTRY, create_from_spec, parse_spec

    name, raw = parse_spec(args.spec)
    info = REGISTRY.info(name)
    print(info.describe())
    if info.description:
        print("\n" + info.description)
    if info.method_class is not None and overrides(info.method_class, "describe_variant"):
        method = create_from_spec(args.spec) if raw else REGISTRY.create(name)
        facts = method.describe_variant()
        if facts:
            print()
        for key, value in facts.items():
            print(f"{key}: {value}")
    return 0
