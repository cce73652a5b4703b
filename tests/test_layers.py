"""Imports flow one way: physics → observation → inference → diagnostics → report → top level.

Every module of the package is parsed with :mod:`ast`; every import (at module level or inside a function,
absolute or relative) that names a ``bayes_disc`` module is mapped to the layer of the importing module
and of the imported one. An import from a higher layer into a lower one fails the test, which lists every
offending import with its file and line.

Layers, lowest first:

0. ``bayes_disc._version`` — the version string; imports nothing;
1. ``physics`` — constants, frames, equations of motion, simulator;
2. ``observation`` and ``video`` — recorded data: marker files, cases, synthetic flights, configuration
   blocks; ``video`` turns footage into marker tracks (docs/data-formats.md), so it is an observation module and may
   import only physics and observation;
3. ``inference`` — the statistical problem (``inference.model``), least squares and profiles
   (``inference.fitting``), sampling (``inference.sampling``) and results (``inference.results``); its
   sub-packages form one layer;
4. ``diagnostics`` — identifiability and missing physics (they refit, so they use inference);
5. ``report`` — HTML report and figures of a run;
6. the top level — ``cli``, ``api``, the packages ``jobs`` (the command jobs) and ``calibration``, ``_logging``, the
   package ``__init__`` and ``__main__``: orchestration (run, then report) and the user interfaces.

Imports within one layer (and between ``observation`` and ``video``) are allowed.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from conftest import REPO

PACKAGE = "bayes_disc"
LAYER_OF_PART = {"_version": 0, "physics": 1, "observation": 2, "video": 2, "inference": 3, "diagnostics": 4,
                 "report": 5}
TOP = 6
TOP_MODULES = {"cli", "api", "jobs", "calibration", "_logging", "__init__", "__main__"}


def module_name(root: Path, file: Path) -> str:
    """Dotted module name of ``file`` under the folder ``root`` that holds the package."""
    parts = list(file.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def layer(module: str) -> int:
    """Layer of a dotted ``bayes_disc`` module name; an unknown top-level part is an error."""
    parts = module.split(".")
    assert parts[0] == PACKAGE, module
    if len(parts) == 1:
        return TOP
    if parts[1] in LAYER_OF_PART:
        return LAYER_OF_PART[parts[1]]
    if parts[1] in TOP_MODULES:
        return TOP
    raise ValueError(f"module {module} belongs to no layer: add it to LAYER_OF_PART or TOP_MODULES")


def _is_package(file: Path) -> bool:
    return file.name == "__init__.py"


def imported_modules(root: Path, file: Path) -> list[tuple[int, str]]:
    """(line, dotted module) of every ``bayes_disc`` import in ``file``, wherever it stands."""
    tree = ast.parse(file.read_text(encoding="utf-8"), filename=str(file))
    here = module_name(root, file)
    package = here if _is_package(file) else here.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == PACKAGE]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[:len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            if base.split(".")[0] != PACKAGE:
                continue
            for alias in node.names:
                # `from pkg import name`: name is a submodule when a file or folder of that name exists
                candidate = root.joinpath(*base.split("."), alias.name)
                if candidate.with_suffix(".py").is_file() or candidate.is_dir():
                    found.append((node.lineno, f"{base}.{alias.name}"))
                else:
                    found.append((node.lineno, base))
    return found


def upward_imports(root: Path) -> list[str]:
    """Every import of a higher layer by a lower one in the package under ``root``, as readable lines."""
    bad = []
    for file in sorted((root / PACKAGE).rglob("*.py")):
        here = module_name(root, file)
        lo = layer(here)
        for line, target in imported_modules(root, file):
            if layer(target) > lo:
                bad.append(f"{file.relative_to(root)}:{line}: {here} (layer {lo}) imports {target} "
                           f"(layer {layer(target)})")
    return bad


def test_imports_flow_one_way():
    bad = upward_imports(REPO)
    assert not bad, "imports against the layer order:\n" + "\n".join(bad)


def test_every_module_has_a_layer():
    for file in (REPO / PACKAGE).rglob("*.py"):
        layer(module_name(REPO, file))          # raises for a module outside every layer


def _plant(root: Path, rel: str, text: str) -> None:
    path = root / PACKAGE / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_checker_catches_planted_upward_imports(tmp_path):
    """The checker is able to fail: module-level, function-local, relative and absolute upward imports."""
    _plant(tmp_path, "__init__.py", "from ._version import __version__\n")
    _plant(tmp_path, "_version.py", "__version__ = '0'\n")
    _plant(tmp_path, "physics/__init__.py", "")
    _plant(tmp_path, "physics/kernel.py", "import numpy as np\nfrom . import __name__ as _n\n")
    _plant(tmp_path, "observation/__init__.py", "")
    _plant(tmp_path, "observation/markers.py", "from ..physics import kernel\n")            # allowed
    _plant(tmp_path, "inference/run.py", "def f():\n    from ..report import build_report\n")   # local, relative
    _plant(tmp_path, "report/__init__.py", "build_report = None\n")
    _plant(tmp_path, "report/content.py", "from .. import __version__\n")                      # package top
    _plant(tmp_path, "video/track.py", "import bayes_disc.inference.run\n")                    # absolute
    _plant(tmp_path, "cli.py", "from .report import build_report\nfrom .physics.kernel import np\n")  # allowed
    bad = upward_imports(tmp_path)
    assert len(bad) == 3, bad
    assert any("inference/run.py:2" in b and "bayes_disc.report" in b for b in bad)
    assert any("report/content.py:1" in b and "imports bayes_disc (layer 6)" in b for b in bad)
    assert any("video/track.py:1" in b and "bayes_disc.inference.run" in b for b in bad)


def test_module_outside_every_layer_is_an_error(tmp_path):
    _plant(tmp_path, "extras/thing.py", "")
    with pytest.raises(ValueError, match="belongs to no layer"):
        upward_imports(tmp_path)
