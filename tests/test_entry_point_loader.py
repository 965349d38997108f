"""Issue 29.5: one entry-point loader. Methods, networks, metrics, datasets, commands and paper references all
load their plugins through lfbench.utils.registry.Registry: one "Unknown X. Available: ..." message, one
handling of a broken plugin (left out, named in ``load_errors``, the others working)."""

from __future__ import annotations

import re
import sys
import uuid
from pathlib import Path

import pytest
from helpers import write_dist_info

from lfbench.utils.errors import SpecError
from lfbench.utils.registry import Registry

ROOT = Path(__file__).resolve().parent.parent


def test_only_the_registry_reads_entry_points():
    """No module but lfbench/utils/registry.py asks importlib.metadata for a group's entry points (the CLI's
    commands, the references and the metrics each had a loop of their own)."""
    readers = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "lfbench").rglob("*.py")
                     if re.search(r"metadata\.entry_points\(|def entry_points\(", p.read_text(encoding="utf-8")))
    assert readers == ["lfbench/utils/registry.py"]


def test_commands_are_a_registry_of_lazy_modules():
    from lfbench.cli import BUILTIN_COMMANDS, command_registry

    commands = command_registry()
    assert isinstance(commands, Registry) and commands.group == "lfbench.commands"
    names = commands.registered()
    assert names[:len(BUILTIN_COMMANDS)] == list(BUILTIN_COMMANDS)  # the built-ins first, in their order
    assert "convert-keras" in names and commands.target("convert-keras") == "lfbench_methods.convert_keras"
    with pytest.raises(SpecError, match=r"^Unknown command 'nope'\. Available: ablate, bench, "):
        commands.get("nope")


def test_references_are_a_registry_and_a_broken_one_is_left_out(tmp_path, monkeypatch):
    """A reference whose file names another reference, and one whose package does not exist: both left out
    with why; the shipped one stays."""
    from lfbench.reports import reference as ref

    tag = uuid.uuid4().hex[:8]
    site = tmp_path / "site"
    package = site / f"refpkg_{tag}"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("raise RuntimeError('a reference is read without importing its package')\n")
    shipped = (ROOT / "methods" / "subfocal" / "paper.toml").read_text(encoding="utf-8")
    (package / "paper.toml").write_text(shipped, encoding="utf-8")  # says name = "subfocal-tci2023"
    write_dist_info(site, f"refpkg-{tag}", "[lfbench.references]\n"
                    f"misnamed-{tag} = refpkg_{tag}:paper.toml\nmissing-{tag} = refpkg_{tag}_absent:paper.toml\n")
    monkeypatch.syspath_prepend(str(site))
    references = Registry("reference", ref.Reference, group=ref.ENTRY_POINT_GROUP, load=ref.REFERENCES.load)
    assert references.names() == ["subfocal-tci2023"]
    assert references.load_errors[f"misnamed-{tag}"] == (
        f"SpecError: {package / 'paper.toml'}: reference 'misnamed-{tag}': its file says name = 'subfocal-tci2023'")
    assert f"missing-{tag}" in references.load_errors and f"refpkg_{tag}" not in sys.modules
    with pytest.raises(SpecError, match=rf"Unknown reference 'misnamed-{tag}' \(plugin failed to load: SpecError"):
        references.get(f"misnamed-{tag}")
    assert ref.get_reference("subfocal-tci2023") is ref.REFERENCES.get("subfocal-tci2023")
    assert ref.list_references() == {"subfocal-tci2023": ref.REFERENCES.get("subfocal-tci2023")}


def test_a_plugin_cannot_replace_a_builtin_entry():
    """lfbench's own entries of a group (``builtins``) load first; a plugin's of the same name is left out."""
    from importlib import metadata

    class Fake(Registry):
        def entry_points(self):  # what the install's metadata would add: a plugin named like a built-in
            return [*super().entry_points(), metadata.EntryPoint("own", "elsewhere:thing", "g")]

    reg = Fake("thing", group="g", builtins={"own": "lfbench.utils.registry:describe"})
    assert reg.names() == ["own"] and reg.get("own").__name__ == "describe"
    assert reg.load_errors == {"own": "elsewhere:thing would replace a built-in thing; left out"}
