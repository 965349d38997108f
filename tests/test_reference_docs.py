"""The reference docs of the training config and the ablation spec (docs/*.md) are generated from the one
place every option is declared (issue 22.11): this fails when a committed file is stale. Regenerate with the
command named in the file's first line."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from lfbench.ablation import reference as ablation_reference
from lfbench.ablation.spec import SpecFile
from lfbench.data import dataset_file
from lfbench.data.dataset_file import DatasetFile
from lfbench.reports import reference_doc
from lfbench.reports.reference import Reference
from lfbench.training import reference as training_reference
from lfbench.training.config import TrainConfig
from lfbench.utils.options import option_fields

REPO = Path(__file__).resolve().parents[1]
DOCS = [(training_reference, REPO / "docs" / "training-config.md", TrainConfig),
        (ablation_reference, REPO / "docs" / "ablation-spec.md", SpecFile),
        (reference_doc, REPO / "docs" / "paper-reference.md", Reference),
        (dataset_file, REPO / "docs" / "dataset-toml.md", DatasetFile)]


def _keys(cls: type) -> set[str]:
    out = set()
    for f, opt, kind in option_fields(cls):
        if not opt.rest:
            out.add(f.name)
        for inner in (kind, *getattr(kind, "__args__", ())):
            if dataclasses.is_dataclass(inner):
                out |= _keys(inner)
    return out


@pytest.mark.parametrize(("module", "path", "declared"), DOCS, ids=["training-config", "ablation-spec",
                                                                              "paper-reference", "dataset-toml"])
def test_the_committed_reference_is_what_the_declarations_generate(module, path, declared):
    text = path.read_text(encoding="utf-8")
    assert module.COMMAND in text.splitlines()[0]  # the header names the command that regenerates it
    assert text == module.reference(), f"{path.name} is stale: run `{module.COMMAND}`"
    for key in _keys(declared):  # every declared option has a row
        assert f"| `{key}` |" in text, key


def test_readme_and_help_point_at_the_references(capsys):
    from lfbench.cli import main

    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for _, path, _ in DOCS:
        assert f"docs/{path.name}" in readme
    for command, name in (("train", "training-config.md"), ("ablate", "ablation-spec.md")):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert f"docs/{name}" in text and ".py" not in text.split("options:")[0]  # no source path to read
