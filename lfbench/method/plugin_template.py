"""``lfbench new-plugin NAME --out DIR``: a plugin package that ``pip install DIR`` installs and that passes
``lfbench check-plugin NAME``: a pyproject with the entry point, the plugin module (a small cost-volume
network whose sampling shows lfbench's sign convention in code) and a training config.

:func:`plugin_files` gives the files (relative path -> text), filled in from the skeleton's real files in
``lfbench/method/plugin_skeleton/`` (each ``<path>.tmpl``; ``package/`` becomes the plugin's package,
``train.toml`` its ``train_<name>.toml``); :func:`write_plugin` writes them as one set.
"""

from __future__ import annotations

import re
import shutil
from importlib import resources
from pathlib import Path

from lfbench.utils.atomic import fresh_dir
from lfbench.utils.errors import SpecError

#: What a new plugin's network name may be: it becomes a method name, an entry point and (with ``_`` for ``-``)
#: part of a Python package name.
NAME_PATTERN = re.compile(r"[a-z][a-z0-9_-]{0,39}")

#: The skeleton's files (package data beside this module: real files, each ``<path>.tmpl``): the path of each
#: in a new plugin, where ``package`` is the plugin's package and ``train.toml`` its training config.
SKELETON = "plugin_skeleton"


def _skeleton() -> dict[str, str]:
    """The skeleton's files, relative path (without ``.tmpl``) -> text with the placeholders ``__NAME__``..."""
    root = resources.files("lfbench.method").joinpath(SKELETON)
    files = {}
    for rel in ("pyproject.toml", "README.md", "package/__init__.py", "package/plugin.py", "train.toml"):
        files[rel] = root.joinpath(*f"{rel}.tmpl".split("/")).read_text(encoding="utf-8")
    return files


def check_name(name: str) -> None:
    """SpecError unless ``name`` fits :data:`NAME_PATTERN`."""
    if not NAME_PATTERN.fullmatch(name):
        raise SpecError(f"plugin name {name!r}: use 1 to 40 lower-case letters, digits, '_' or '-', starting with a "
                        "letter (it names the network, its entry point and its package)")


def plugin_files(name: str) -> dict[str, str]:
    """The files of a new plugin for network ``name`` (relative path -> text)."""
    check_name(name)
    ident = name.replace("-", "_")
    package = f"lfbench_{ident}"
    words = {"__NAME__": name, "__DIST__": name.replace("_", "-"), "__PACKAGE__": package, "__FILE__": ident,
             "__CLASS__": "".join(part.capitalize() for part in ident.split("_") if part)}

    def fill(text: str) -> str:
        for key, value in words.items():
            text = text.replace(key, value)
        return text

    renamed = {"package/": f"{package}/", "train.toml": f"train_{ident}.toml"}
    out = {}
    for rel, text in _skeleton().items():
        for old, new in renamed.items():
            rel = rel.replace(old, new) if rel.startswith(old) else rel
        out[rel] = fill(text)
    return out


def write_plugin(name: str, out: str | Path) -> list[Path]:
    """Write the plugin of :func:`plugin_files` into the folder ``out`` (created; it must not exist or be
    empty) as one set: written into a fresh folder beside it, then renamed into place. Returns the files."""
    files = plugin_files(name)
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SpecError("exists and is not an empty folder: choose a new --out", out)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = fresh_dir(out.parent, f".{out.name}.", ".new")
    try:
        for rel, text in files.items():
            (staging / rel).parent.mkdir(parents=True, exist_ok=True)
            (staging / rel).write_text(text, encoding="utf-8")
        if out.exists():
            out.rmdir()
        staging.rename(out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return [out / rel for rel in files]


__all__ = ["plugin_files", "write_plugin", "check_name", "NAME_PATTERN"]
