"""The ``lfbench`` command line. Each subcommand lives in lfbench/cli/<name>.py with
``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; heavy imports happen inside run().

Plugins add subcommands the same way: a module with ``HELP``, ``add_arguments`` and ``run`` (light at
import: every ``lfbench`` call imports it to build the parser), named by an entry point of the group
``lfbench.commands`` (``convert-keras = "lfbench_methods.subfocal.cli"``). A plugin command cannot
replace a built-in one; one that fails to load is left out with a warning on stderr.

Errors caused by input (files, specs, options) print one line on stderr and exit with code 2.
Library messages go through ``logging`` and are shown on stderr (``-v``: also debug, ``-q``: only warnings).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
import warnings
from collections.abc import Sequence
from types import ModuleType

from lfbench.utils.errors import LFBenchError
from lfbench.utils.log import configure_cli_logging

COMMAND_GROUP = "lfbench.commands"
COMMANDS = {
    "evaluate": "lfbench.cli.evaluate",
    "predict": "lfbench.cli.predict",
    "methods": "lfbench.cli.methods",
    "info": "lfbench.cli.info",
    "demo": "lfbench.cli.demo",
    "report": "lfbench.cli.report",
    "synth": "lfbench.cli.synth",
    "train": "lfbench.cli.train",
    "ablate": "lfbench.cli.ablate",
    "regress": "lfbench.cli.regress",
    "validate-submission": "lfbench.cli.validate_submission",
    "bench": "lfbench.cli.bench",
}


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit 2) instead of a usage block."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from lfbench import __version__

    parser = _Parser(prog="lfbench", description="Light-field depth estimation on the HCI 4D Light Field Benchmark.")
    parser.add_argument("--version", action="version", version=f"lfbench {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more messages (debug)")
    parser.add_argument("-q", "--quiet", dest="log_quiet", action="store_true",
                        help="only warnings and errors on stderr")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name, module in [*((n, importlib.import_module(m)) for n, m in COMMANDS.items()), *plugin_commands()]:
        p = sub.add_parser(name, help=module.HELP, description=module.__doc__)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def plugin_commands() -> list[tuple[str, ModuleType]]:
    """(name, module) of the ``lfbench.commands`` entry points, sorted by name; a broken one, or one that
    would replace a built-in command, is left out with a one-line warning on stderr."""
    from importlib import metadata

    out = []
    for ep in sorted(metadata.entry_points(group=COMMAND_GROUP), key=lambda e: e.name):
        if ep.name in COMMANDS:
            print(f"lfbench: warning: plugin command {ep.name!r} ({ep.value}) would replace a built-in command; "
                  "left out", file=sys.stderr)
            continue
        try:
            module = ep.load()
            missing = [a for a in ("HELP", "add_arguments", "run") if not hasattr(module, a)]
            if missing:
                raise TypeError(f"{ep.value} has no {', '.join(missing)}")
        except Exception as exc:  # a broken plugin must not break the command line
            print(f"lfbench: warning: plugin command {ep.name!r} failed to load ({type(exc).__name__}: {exc})",
                  file=sys.stderr)
            continue
        out.append((ep.name, module))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    configure_cli_logging(-1 if args.log_quiet else args.verbose)
    with warnings.catch_warnings(record=True) as caught:  # library warnings (torch, Pillow): one line each,
        warnings.simplefilter("default")                  # after the command; dropped when it fails
        try:
            rc = int(args._run(args) or 0)
        except LFBenchError as exc:
            print(f"lfbench {args.command}: error: {exc}", file=sys.stderr)
            return exc.exit_code
        except KeyboardInterrupt:
            print(f"lfbench {args.command}: interrupted", file=sys.stderr)
            return 130
        except BrokenPipeError:
            return 0
        except OSError as exc:  # the system refused a read or write (disk full, permissions): one line too
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"lfbench {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 2
    for w in caught:
        logging.getLogger("lfbench").warning("warning: %s", " ".join(str(w.message).split())[:300])
    return rc


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
