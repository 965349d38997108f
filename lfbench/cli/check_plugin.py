"""Run a registered network against the plugin contract on tiny generated light fields: output shapes and
dtypes, the disparity sign (with --weights: a network with random weights has no sign), the receptive radius,
tiled = untiled, flops(), a save/load round trip and one training step. One line per check (ok, FAIL with what
to fix, skip with why), then a summary. Exit 0 when nothing failed, 1 when a check failed, 2 on bad input (an
unknown network, a bad parameter, an unreadable weights file) or a check that runs past --timeout.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lfbench.cli.argtypes import add_flag
from lfbench.utils.flags import SEED, TIMEOUT

PLUGIN_TIMEOUT_S = 300.0  # s: the checks of a small network on 20x24 px views take seconds
HELP = "check a plugin's network against lfbench's contract (shapes, sign, tiling, flops, save/load, training)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", metavar="NAME", help="registered network, optionally with parameters: NAME[:key=value,...]")
    p.add_argument("--weights", type=Path, default=None, metavar="FILE",
                   help="trained weights (lfbench train writes OUT/final.pt): also checks the disparity's sign")
    add_flag(p, SEED, detail="of the random views and the initialisation")
    add_flag(p, TIMEOUT, default=PLUGIN_TIMEOUT_S, detail="the time each check (the network's constructor, its "
             "forward, ...) may take; past it, one line and exit 2")


def run(args: argparse.Namespace) -> int:
    from lfbench.method.params import coerce_params, parse_spec
    from lfbench.method.trainable import get_trainable
    from lfbench.runs.plugin_check import check_plugin, failed, summary

    name, raw = parse_spec(args.spec)
    trainable = get_trainable(name)  # SpecError listing the networks for an unknown name
    params = coerce_params(raw, trainable.parameters(), name)
    if args.weights is not None and not args.weights.is_file():
        from lfbench.utils.errors import DataError

        raise DataError("weights file not found" if not args.weights.exists() else "not a regular file", args.weights)
    findings = check_plugin(name, params, weights=args.weights, seed=args.seed, timeout=args.timeout)
    for finding in findings:
        print(finding.line())
    print(summary(name, findings))
    return 1 if failed(findings) else 0
