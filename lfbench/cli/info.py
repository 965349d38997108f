"""Describe one method: summary, parameters with types, defaults and help (a network's too), its
description, and method-specific facts (e.g. ``trainable_parameters: N`` for networks, the weights it
loads). Accepts a spec to describe a configured variant."""

from __future__ import annotations

import argparse
from pathlib import Path

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
    network = REGISTRY.network_of(name)
    if network is not None:
        print_network(network, name, raw)
    return 0


def print_network(network: str, name: str, raw: dict[str, str]) -> None:
    """The network's parameter count and FLOPs at 512x512, without weights: the weights' architecture when
    the spec names a weights file, else the network parameters of the spec over the defaults."""
    from lfbench.method.params import coerce_params
    from lfbench.method.trainable import get_trainable, network_summary

    trainable = get_trainable(network)
    accepted = trainable.parameters()
    params = coerce_params({k: v for k, v in raw.items() if k in accepted}, accepted, name)
    weights = raw.get("weights")
    if weights and Path(weights).expanduser().is_file():
        params = {**trainable.stored_config(Path(weights).expanduser()), **params}
        built = "with the weights' architecture"
    else:
        built = "with " + (", ".join(f"{k}={v}" for k, v in params.items()) if params else "its defaults")
    facts = network_summary(trainable, params)
    print(f"\nnetwork {trainable.name!r} ({built}, no weights needed):")
    print(f"  parameters: {facts['parameters']:,} ({facts['trainable']:,} trainable)")
    flops = facts["flops"]
    if flops is None:
        print("  FLOPs: not declared (the network's flops() hook)")
    else:
        parts = ", ".join(f"{k} {_giga(v)}" for k, v in flops.items() if k != "total")
        total = f"  FLOPs of one forward pass at 512x512: {_giga(flops['total'])} GFLOP"
        print(total + (f" ({parts})" if parts else ""))


def _giga(flops: float) -> str:
    g = flops / 1e9
    return f"{g:,.0f}" if g >= 1000 else f"{g:.4g}"
