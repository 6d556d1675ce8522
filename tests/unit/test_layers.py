"""The architecture, checked: no import circles, layers that run one way, and a core with no I/O.

Read from the source with ``ast`` (nothing is imported), so a lazy import inside a
function, or one only for type checking, counts as much as one at the top: a circle
is a circle wherever it hides.  ``make check`` runs import-linter on the contracts in
pyproject.toml as well; the sans-I/O world's modules are listed there, once, and read here.
"""

from __future__ import annotations

import ast
import functools
import tomllib
from pathlib import Path

import pytest

from tests.conftest import ROOT

pytestmark = pytest.mark.unit

PACKAGES = {
    "pfp_service": ROOT / "pfp_service",
    "pfp_clients": ROOT / "clients" / "pfp_clients",
    "benchmarks": ROOT / "benchmarks",
}
_CONTRACTS = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
# The sans-I/O parts: they take numbers and time as values and return values (STYLE.md, rule 1);
# the world's are the sources of the import-linter contract that forbids them zenoh, time and the rest.
WORLD = next(c["source_modules"] for c in _CONTRACTS if "sans-I/O world" in c["name"])
SANS_IO = (
    "pfp_service/core/",
    *(m.replace(".", "/") + ("/" if (ROOT / m.replace(".", "/")).is_dir() else ".py") for m in WORLD),
)
IO_MODULES = {"time", "os", "socket", "threading", "logging", "zenoh", "subprocess", "asyncio", "sqlite3"}
# What is still to mend, named so that nothing new slips in; each entry is a debt, not a rule.
KNOWN: set[str] = set()


def _modules() -> dict[str, Path]:
    out = {}
    for top, base in PACKAGES.items():
        for path in base.rglob("*.py"):
            parts = [top, *path.relative_to(base).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


MODULES = _modules()


# Each test reads every module's imports: parsed once, not once a test.
@functools.cache
def _imports(path: Path) -> list[tuple[str, bool]]:
    """(module, only for type checking) for every import in the file, relative ones resolved."""
    tree = ast.parse(path.read_text(), str(path))
    typing_only: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            typing_only |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, id(node) in typing_only) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for a in node.names:  # `from pkg import submodule` names the submodule itself
                sub = f"{node.module}.{a.name}"
                out.append((sub if sub in MODULES else node.module, id(node) in typing_only))
    return out


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for mod, path in MODULES.items():
        for name, _typing_only in _imports(path):  # type-checking imports included (issue 31)
            if name in MODULES and name != mod:
                graph[mod].add(name)
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _package_inits_excluded(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    # A package's __init__ only re-exports its modules: an edge into it stands for the module
    # that defines the name, which the modules of the package itself never take that way.
    packages = {m for m, p in MODULES.items() if p.name == "__init__.py"}
    return {m: {w for w in ws if w not in packages} for m, ws in graph.items() if m not in packages}


def test_no_import_circles():
    circles = {"circle: " + ", ".join(c) for c in _circles(_package_inits_excluded(_graph()))}
    assert circles <= KNOWN, f"import circles: {sorted(circles - KNOWN)}"


def test_the_layers_run_one_way_pfp_clients_to_pfp_service():
    offenders = {
        f"upward: {mod}: {name}"
        for mod, path in MODULES.items()
        if mod.startswith("pfp_service")
        for name, _ in _imports(path)
        if name.split(".")[0] == "pfp_clients"
    }
    assert offenders <= KNOWN, sorted(offenders - KNOWN)


def test_the_core_and_the_world_do_no_io():
    offenders = set()
    for path in MODULES.values():
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(SANS_IO):
            offenders |= {f"io: {rel}: {n}" for n, _ in _imports(path) if n.split(".")[0] in IO_MODULES}
    assert offenders <= KNOWN, sorted(offenders - KNOWN)


def test_the_checks_can_fail():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []
