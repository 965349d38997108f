"""The ``lfbench`` command line. Each subcommand lives in lfbench/cli/<name>.py with ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``; heavy imports happen inside run().

Plugins add subcommands the same way: a module with ``HELP``, ``add_arguments`` and ``run``, named by an
entry point of the group ``lfbench.commands`` (``convert-keras = "lfbench_methods.convert_keras"``).
Commands are registered lazily (lfbench.utils.registry): a command's module is imported only when that
command runs; ``lfbench --help`` reads a plugin command's ``HELP = "..."`` from its source without
importing it. So starting ``lfbench`` imports neither torch nor any plugin. A plugin command cannot
replace a built-in one (it is left out with a warning); one that fails to load is an error when it is
run and a warning where ``--help`` lists it.

Errors caused by input (files, specs, options) print one line on stderr and exit with code 2; a stop on
SIGINT/SIGTERM that can be resumed prints one line (``stopped at ...``, not ``error:``) and exits with 130.
Library messages go through ``logging`` and are shown on stderr (``-v``: also debug, ``-q``: only warnings).
"""

from __future__ import annotations

import argparse
import ast
import logging
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from lfbench.utils.errors import Interrupted, LFBenchError
from lfbench.utils.log import configure_cli_logging
from lfbench.utils.registry import Lazy, Registry

COMMAND_GROUP = "lfbench.commands"
BUILTIN_COMMANDS = {
    "evaluate": "lfbench.cli.evaluate",
    "predict": "lfbench.cli.predict",
    "methods": "lfbench.cli.methods",
    "datasets": "lfbench.cli.datasets",
    "info": "lfbench.cli.info",
    "demo": "lfbench.cli.demo",
    "report": "lfbench.cli.report",
    "synth": "lfbench.cli.synth",
    "train": "lfbench.cli.train",
    "ablate": "lfbench.cli.ablate",
    "regress": "lfbench.cli.regress",
    "validate-submission": "lfbench.cli.validate_submission",
    "bench": "lfbench.cli.bench",
    "check-plugin": "lfbench.cli.check_plugin",
    "check-dataset": "lfbench.cli.check_dataset",
    "new-plugin": "lfbench.cli.new_plugin",
}
_HELP_BYTES = 1 << 20  # the most of a plugin command's source read for its HELP


@runtime_checkable
class Command(Protocol):
    """What a command module provides (checked when it is imported)."""

    HELP: str

    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit 2) instead of a usage block."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def command_registry() -> Registry[Any]:
    """The built-in commands and the plugins' (``lfbench.commands`` entry points), none imported yet (each a
    :class:`~lfbench.utils.registry.Lazy` of its module). A plugin command named like a built-in one is left
    out (with a one-line warning on stderr)."""
    commands: Registry[Any] = Registry("command", Command, group=COMMAND_GROUP, builtins=BUILTIN_COMMANDS,
                                       load=lambda ep: Lazy(ep.value))
    commands.names()  # every entry point read (nothing imported)
    for name, why in commands.load_errors.items():
        print(f"lfbench: warning: plugin command {name!r}: {why}", file=sys.stderr)
    return commands


def load_command(commands: Registry[Any], name: str) -> Any:
    """The module of command ``name``, imported now; a plugin's that fails to import, or lacks HELP,
    add_arguments or run, is an LFBenchError naming it."""
    target = commands.target(name)
    if target is not None and name not in BUILTIN_COMMANDS:
        try:
            module = Lazy(target).load()
        except Exception as exc:  # noqa: BLE001 - a broken plugin: one line, whatever it raised
            raise LFBenchError(f"plugin command {name!r} failed to load ({type(exc).__name__}: {exc})") from None
        missing = [a for a in ("HELP", "add_arguments", "run") if not hasattr(module, a)]
        if missing:
            raise LFBenchError(f"plugin command {name!r} failed to load (TypeError: {target} has no "
                               f"{', '.join(missing)})")
    return commands.get(name)


def command_help(commands: Registry[Any], name: str) -> str:
    """The one-line help of a command for ``lfbench --help``, read from its module's source without importing
    it (or from the module, if imported already): ``lfbench --help`` imports no command. A built-in command
    whose HELP is not a string literal is imported for it."""
    target = commands.target(name)
    if target is None:
        return getattr(load_command(commands, name), "HELP", "")
    text = static_help(target)
    if name in BUILTIN_COMMANDS and text is None:
        return getattr(load_command(commands, name), "HELP", "")
    if text is None:
        print(f"lfbench: warning: plugin command {name!r} ({target}): its HELP could not be read", file=sys.stderr)
        return "(plugin command)"
    return text


def static_help(target: str) -> str | None:
    """``HELP = "..."`` of the module ``target`` names, read from its source file without importing it (its
    parent packages are not imported either), or None."""
    module = target.partition(":")[0]
    if module in sys.modules:
        text = getattr(sys.modules[module], "HELP", None)
        return text if isinstance(text, str) else None
    origin = _module_file(module)
    if origin is None:
        return None
    try:
        with open(origin, "rb") as f:
            source = f.read(_HELP_BYTES)
        tree = ast.parse(source)
    except (OSError, SyntaxError, ValueError):
        return None
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "HELP" for t in node.targets):
            if isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
                return node.value.value
    return None


def _module_file(module: str) -> str | None:
    """The source file of ``module`` as the import system would find it, without importing it or its parents."""
    path = None
    spec = None
    parts = module.split(".")
    for i in range(len(parts)):
        name = ".".join(parts[: i + 1])
        spec = None
        for finder in sys.meta_path:
            find = getattr(finder, "find_spec", None)
            if find is None:
                continue
            try:
                spec = find(name, path)
            except (ImportError, ValueError, AttributeError):
                spec = None
            if spec is not None:
                break
        if spec is None:
            return None
        path = spec.submodule_search_locations
    origin = getattr(spec, "origin", None)
    return origin if origin and Path(origin).suffix == ".py" else None


def _command_in(argv: Sequence[str]) -> str | None:
    """The subcommand of ``argv``: its first argument that is not a top-level option."""
    for arg in argv:
        if arg == "--":
            return None
        if not arg.startswith("-"):
            return arg
    return None


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The parser: every command listed with its help; the arguments of the command ``argv`` names (all
    of them when ``argv`` is None) are added, which imports that command's module only."""
    from lfbench import __version__

    parser = _Parser(prog="lfbench", description="Light-field depth estimation on the HCI 4D Light Field Benchmark.")
    parser.add_argument("--version", action="version", version=f"lfbench {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more messages (debug)")
    parser.add_argument("-q", "--quiet", dest="log_quiet", action="store_true",
                        help="only warnings and errors on stderr")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    commands = command_registry()
    chosen = _command_in(argv) if argv is not None else None
    for name in commands.registered():
        if argv is not None and name != chosen:
            sub.add_parser(name, help=command_help(commands, name) if chosen is None else argparse.SUPPRESS)
            continue
        module = load_command(commands, name)
        p = sub.add_parser(name, help=module.HELP, description=module.__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        parser = build_parser(argv)
    except LFBenchError as exc:  # a plugin command that cannot be loaded
        print(f"lfbench: error: {exc}", file=sys.stderr)
        return exc.exit_code
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    configure_cli_logging(-1 if args.log_quiet else args.verbose)
    with warnings.catch_warnings(record=True) as caught:  # library warnings (torch, Pillow): one line each,
        warnings.simplefilter("default")                  # after the command; dropped when it fails
        try:
            rc = int(args._run(args) or 0)
        except Interrupted as exc:  # a stop, not an error: the work is kept and can be resumed
            print(f"lfbench {args.command}: {exc}", file=sys.stderr)
            return exc.exit_code
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
