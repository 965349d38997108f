"""Every Python package folder is installed (a non-editable install must not drop a subpackage)."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_package_folder_is_listed_in_pyproject():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    dirs = {"lfbench": ROOT / "lfbench", "lfbench_methods": ROOT / "methods"}
    found = set()
    for top, folder in dirs.items():
        for init in folder.rglob("__init__.py"):
            rel = init.parent.relative_to(folder).parts
            found.add(".".join((top, *rel)))
    assert found == listed


def test_shipped_weights_are_package_data():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "weights/*.pt" in config["package-data"]["lfbench_methods"]


def _torch_requirement():
    from packaging.requirements import Requirement

    deps = [Requirement(d) for d in tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]]
    found = [r for r in deps if r.name == "torch"]
    assert len(found) == 1
    return found[0]


def test_torch_is_a_lower_bound_so_an_installed_build_is_kept():
    """pip keeps an installed torch that satisfies the requirement: any 2.x build from 2.4 on, CUDA or CPU."""
    spec = _torch_requirement().specifier
    assert spec and all(s.operator == ">=" for s in spec)  # no ==, ~=, <, != pin of one build
    for version in ("2.4.0", "2.5.1+cu121", "2.7.1+cu128", "2.13.0", "2.13.0+cpu", "2.15.0+cu130"):
        assert spec.contains(version), version
    assert not spec.contains("2.3.1")


def test_quick_start_and_ci_pin_the_cpu_build_through_the_constraints_file():
    from packaging.requirements import Requirement

    lines = [ln.strip() for ln in (ROOT / "constraints" / "cpu.txt").read_text().splitlines()]
    pins = [Requirement(ln) for ln in lines if ln and not ln.startswith("#")]
    assert [str(p) for p in pins] == ["torch==2.13.0"]
    assert _torch_requirement().specifier.contains("2.13.0")  # the pin satisfies the package's bound
    install = 'pip install -c constraints/cpu.txt -e ".[test]"'
    readme = (ROOT / "README.md").read_text()
    quick = readme.split("## Quick start", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    assert install in quick  # still the README's one install command
    assert f"python -m {install.replace('pip install', 'pip install -q')}" in (ROOT / ".ci" / "run").read_text()


def test_the_code_calls_newer_torch_apis_only_behind_a_check():
    """torch >= 2.9's per-backend fp32_precision flags are the one newer API lfbench uses; every use sits in
    lfbench/utils/hardware.py behind _new_precision_api() (older torch takes the allow_tf32 branch)."""
    users = [p for top in ("lfbench", "methods") for p in (ROOT / top).rglob("*.py")
             if "fp32_precision" in p.read_text(encoding="utf-8")]
    assert [p.relative_to(ROOT).as_posix() for p in users] == ["lfbench/utils/hardware.py"]
    text = (ROOT / "lfbench" / "utils" / "hardware.py").read_text(encoding="utf-8")
    assert text.count("if _new_precision_api():") == 2


def test_the_plugin_skeleton_is_package_data():
    """`lfbench new-plugin` reads lfbench/method/plugin_skeleton/: every file there must be installed."""
    import fnmatch

    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["lfbench"]
    files = [p.relative_to(ROOT / "lfbench").as_posix()
             for p in (ROOT / "lfbench" / "method" / "plugin_skeleton").rglob("*") if p.is_file()]
    assert len(files) == 5
    assert all(any(fnmatch.fnmatchcase(f, g) and "/" not in f[len(g.rsplit("/", 1)[0]) + 1:] for g in globs)
               for f in files)
