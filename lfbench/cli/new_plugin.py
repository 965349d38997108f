"""Write a new plugin package into DIR: pyproject.toml (the lfbench.methods entry point), the plugin module
(a small cost-volume network registered as NAME, every hook filled in), a training config and a README with
the commands. It passes `lfbench check-plugin NAME` once installed (`pip install DIR`). DIR must not exist or
be empty; the files are written as one set.
"""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "write a new plugin package (a network that passes check-plugin, its pyproject and training config)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("name", metavar="NAME", help="the network's name (lower-case letters, digits, '_' or '-')")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="folder to write (new or empty)")


def run(args: argparse.Namespace) -> int:
    from lfbench.method.plugin_template import check_name, write_plugin
    from lfbench.method.registry import REGISTRY
    from lfbench.utils.errors import SpecError

    check_name(args.name)
    taken = REGISTRY.find(args.name)
    if taken is not None:
        raise SpecError(f"a method or network named {args.name!r} is registered already ({taken.source}): "
                        "choose another NAME")
    for path in write_plugin(args.name, args.out):
        print(path)
    print(f"next: pip install {args.out} && lfbench check-plugin {args.name}")
    return 0
