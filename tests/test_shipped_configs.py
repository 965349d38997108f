"""Every shipped training config and ablation spec (configs/, ablations/, examples/tiny_plugin/) parses to
the same values as before the options were declared once (issue 21.4): the parsed dataclasses and the
cells' training configs are compared with tests/data/shipped_configs.json, recorded from the hand-written
parsers they replaced (since updated for deliberate changes: paper_methods absent is None, "the
reference's own", and the spec's reference; [validation] scorer, the paper author's on UrbanLF-Syn). Regenerate
it only for a deliberate change of a shipped file or a parsed value:
``python tests/test_shipped_configs.py > tests/data/shipped_configs.json``."""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from lfbench.ablation.spec import AblationSpec, load_spec
from lfbench.training.config import TrainConfig

REPO = Path(__file__).resolve().parents[1]
SNAPSHOT = REPO / "tests" / "data" / "shipped_configs.json"
HCI_ROOT = "/hci-root"  # $LFBENCH_HCI_ROOT while parsing: the shipped files name it
URBANLF_ROOT = "/urbanlf-root"  # $LFBENCH_URBANLF_ROOT likewise (configs/subfocal_urbanlf.toml)
CONFIGS = ("configs/*.toml", "examples/tiny_plugin/train_tiny.toml")
SPECS = ("ablations/*.toml", "examples/tiny_plugin/ablate_channels.toml")


def shipped(patterns: tuple[str, ...]) -> list[str]:
    return sorted(str(p.relative_to(REPO)) for pattern in patterns for p in REPO.glob(pattern))


def plain(x: Any) -> Any:
    """JSON-able, with the checkout's path replaced by <repo> (the snapshot must not depend on it)."""
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {f.name: plain(getattr(x, f.name)) for f in dataclasses.fields(x)}
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items() if k != "source"}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, Path):
        x = str(x)
    if isinstance(x, str):
        return x.replace(str(REPO), "<repo>")
    return x


def config_view(cfg: TrainConfig) -> dict[str, Any]:
    fields = plain(cfg)
    fields.pop("source", None)
    return {"fields": fields, "to_dict": plain(cfg.to_dict())}


def budget_view(spec: AblationSpec) -> dict[str, Any]:
    b = spec.budget
    model = b.model if hasattr(b, "model") else ({} if b.width is None else {"width": b.width})
    return {"steps": plain(b.steps), "batch": b.batch, "patch": b.patch, "threads": b.threads, "model": plain(model),
            "label": spec.budget_label()}


def spec_view(spec: AblationSpec) -> dict[str, Any]:
    return {"title": spec.title, "table": spec.table, "base_source": plain(spec.base_source),
            "budget": budget_view(spec), "shared_stage1": spec.shared_stage1, "evaluation": plain(spec.evaluation),
            "methods": plain(spec.methods), "paper_methods": plain(spec.paper_methods), "reference": spec.reference,
            "out": spec.out,
            "seeds": plain(spec.seeds),
            "cells": [{"id": c.id, "values": plain(c.values), "config": plain(c.config), "fingerprint": c.fingerprint,
                       "parsed": plain(c.train_config())} for c in spec.cells]}


@contextlib.contextmanager
def example_plugin_registered() -> Iterator[None]:
    """The example plugin's network and method registered in throw-away registries (as if installed)."""
    from helpers import isolate_registries

    with pytest.MonkeyPatch.context() as mp:
        isolate_registries(mp)
        mp.setenv("LFBENCH_HCI_ROOT", HCI_ROOT)
        mp.setenv("LFBENCH_URBANLF_ROOT", URBANLF_ROOT)
        mp.syspath_prepend(str(REPO / "examples" / "tiny_plugin"))
        try:
            importlib.import_module("lfbench_tiny.plugin")
            yield
        finally:
            for name in [m for m in sys.modules if m == "lfbench_tiny" or m.startswith("lfbench_tiny.")]:
                del sys.modules[name]


def snapshot() -> dict[str, Any]:
    with example_plugin_registered():
        configs = {p: config_view(TrainConfig.from_toml(REPO / p)) for p in shipped(CONFIGS)}
        specs = {p: spec_view(load_spec(REPO / p)) for p in shipped(SPECS)}
    return {"configs": configs, "specs": specs}


def test_every_shipped_file_is_in_the_snapshot():
    recorded = json.loads(SNAPSHOT.read_text(encoding="utf-8"))
    assert sorted(recorded["configs"]) == shipped(CONFIGS)
    assert sorted(recorded["specs"]) == shipped(SPECS)


@pytest.mark.parametrize("kind", ["configs", "specs"])
def test_shipped_files_parse_to_the_recorded_values(kind):
    recorded = json.loads(SNAPSHOT.read_text(encoding="utf-8"))[kind]
    now = snapshot()[kind]
    for path in recorded:  # as JSON text, so that 8 and 8.0 differ
        assert json.dumps(now[path], sort_keys=True) == json.dumps(recorded[path], sort_keys=True), path


def without_none(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: without_none(v) for k, v in x.items() if v is not None}
    if isinstance(x, list):
        return [without_none(v) for v in x if v is not None]
    return x


def test_the_train_toml_of_every_shipped_cell_reads_back_as_its_config():
    """What ``lfbench ablate`` writes as CELL/train.toml (tomli-w) is the cell's config: the same TOML values
    (None entries left out) and the same parsed TrainConfig."""
    import tomllib

    from lfbench.utils.tomlfile import toml_text

    with example_plugin_registered():
        for path in shipped(SPECS):
            for cell in load_spec(REPO / path).cells:
                text = toml_text(cell.config, f"cell {cell.id}\nsecond line")
                assert text.startswith(f"# cell {cell.id}\n# second line\n")
                back = tomllib.loads(text)
                assert json.dumps(back, sort_keys=True) == json.dumps(without_none(cell.config), sort_keys=True)
                assert TrainConfig.from_dict(back) == cell.train_config(), (path, cell.id)


if __name__ == "__main__":
    os.environ.setdefault("LFBENCH_HCI_ROOT", HCI_ROOT)
    os.environ.setdefault("LFBENCH_URBANLF_ROOT", URBANLF_ROOT)
    data = snapshot()  # one line per file: a change shows as the files it touches
    sys.stdout.write("{\n" + ",\n".join(
        f"{json.dumps(kind)}: {{\n" + ",\n".join(f" {json.dumps(p)}: {json.dumps(v, sort_keys=True)}"
                                                 for p, v in sorted(data[kind].items())) + "\n}"
        for kind in ("configs", "specs")) + "\n}\n")
