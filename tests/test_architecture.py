"""The import rules of the README's Architecture section, checked on the source (no module is imported)."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted(p for pkg in ("gttdata", "gttnet") for p in (ROOT / pkg).rglob("*.py"))


@functools.cache
def _imports(path: Path) -> frozenset[str]:
    """Every module name a file imports (``from a.b import c`` gives ``a.b`` and ``a.b.c``)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return frozenset(out)


def _module(path: Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts)


def _offenders(prefixes: tuple[str, ...], allowed: tuple[str, ...]) -> list[str]:
    bad = []
    for path in SOURCES:
        mod = _module(path)
        if mod.startswith(allowed):
            continue
        hits = sorted(m for m in _imports(path) if m.startswith(prefixes))
        if hits:
            bad.append(f"{mod} imports {hits[0]}")
    return bad


def test_sources_found():
    assert len(SOURCES) > 50


def test_nothing_outside_cli_imports_cli():
    cli = ("gttdata.cli", "gttnet.cli")
    assert _offenders(cli, cli + ("gttdata.__main__", "gttnet.__main__")) == []


def test_apps_is_a_leaf_below_cli():
    assert _offenders(("gttnet.apps",), ("gttnet.apps", "gttnet.cli")) == []


@pytest.mark.parametrize("forbidden", ["gttnet", "torch"])
def test_gttdata_never_imports_gttnet_or_torch(forbidden):
    bad = [
        f"{_module(p)} imports {forbidden}"
        for p in SOURCES
        if _module(p).startswith("gttdata")
        and any(m == forbidden or m.startswith(forbidden + ".") for m in _imports(p))
    ]
    assert bad == []


def test_no_citation_of_a_file_outside_the_repository():
    name = "REFERENCE" + ".md"  # spelled in two parts so this file does not match itself
    folders = ("gttdata", "gttnet", "tests", "docs", "recipes", "benchmarks", "scripts")
    tracked = [ROOT / "README.md"] + [
        p for d in folders for p in (ROOT / d).rglob("*") if p.suffix in {".py", ".md", ".yaml"}
    ]
    assert [str(p.relative_to(ROOT)) for p in tracked if name in p.read_text(errors="ignore")] == []
