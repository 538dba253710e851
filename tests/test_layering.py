"""The packages import one way (docs: design/architecture.md, "Layers"): the contracts of
``[tool.importlinter]`` in pyproject.toml hold, every module of ``cosim`` is in one of its three
layers (core, adapters, applications), no import runs back up from a lower layer or package,
and no two modules import each other, directly or in a circle."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("controllers", "cosim")
#: cosim's application modules: they may use the numerical core and the adapters.
APPLICATION = ("cosim.api", "cosim.campaign", "cosim.cli", "cosim.commands", "cosim.hmi",
               "cosim.live", "cosim.tuning")
#: cosim's layers, top down (the layers contract's).
LAYERS = (APPLICATION, ("cosim.adapters",), ("cosim.core",))


def _config() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))[
        "tool"]["importlinter"]


def _graph():
    grimp = pytest.importorskip("grimp")
    return grimp.build_graph(*PACKAGES, exclude_type_checking_imports=True)


def test_the_import_contracts_hold() -> None:
    lint = Path(sys.executable).with_name("lint-imports")
    if not lint.exists():
        pytest.skip("import-linter is not installed (the dev extra)")
    proc = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, check=False)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout


def test_every_cosim_module_is_in_a_layer() -> None:
    """The layers contract names cosim's three layers, and every module of cosim is in one
    (the package's own ``cosim/__init__.py`` aside: it imports nothing, it names the API)."""
    (layers,) = [c["layers"] for c in _config()["contracts"] if c.get("type") == "layers"]
    assert [tuple(p.strip() for p in layer.split(":")) for layer in layers] == list(LAYERS)
    modules = {m for m in _graph().modules if m.startswith("cosim.")}
    unclassified = sorted(m for m in modules if not any(
        m == a or m.startswith(a + ".") for layer in LAYERS for a in layer))
    assert not unclassified, (f"{unclassified}: put them in cosim/core, cosim/adapters or an "
                              "application package")


def test_no_import_runs_back_up() -> None:
    """Issue 59: no module imports one of a layer above its own (19 imports ran from cosim's
    applications up to the adapters' package when it stood beside cosim), and controllers
    imports nothing of cosim."""
    graph = _graph()
    rank = {name: r for r, layer in enumerate(LAYERS) for name in layer}

    def layer_of(module: str) -> int | None:
        if module.startswith("controllers"):
            return len(LAYERS)   # below cosim
        return next((r for name, r in rank.items()
                     if module == name or module.startswith(name + ".")), None)

    up = []
    for m in sorted(graph.modules):
        mine = layer_of(m)
        if mine is None:
            continue
        for d in graph.find_modules_directly_imported_by(m):
            theirs = layer_of(d)
            if theirs is not None and theirs < mine:
                up.append(f"{m} -> {d}")
    assert not up, up


def test_no_module_imports_itself_through_others() -> None:
    graph = _graph()
    modules = sorted(m for m in graph.modules if m.split(".")[0] in PACKAGES)
    edges = {m: sorted(d for d in graph.find_modules_directly_imported_by(m) if d in modules
                       and not m.startswith(d + ".") and d != m) for m in modules}
    cycles = [c for c in _strongly_connected(modules, edges) if len(c) > 1]
    assert not cycles, f"import cycles: {cycles}"


def _strongly_connected(nodes: list[str], edges: dict[str, list[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter
                counter += 1
                stack.append(v)
                on_stack.add(v)
            recurse = False
            for j in range(i, len(edges[v])):
                w = edges[v][j]
                if w not in index:
                    work.append((v, j + 1))
                    work.append((w, 0))
                    recurse = True
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            if recurse:
                continue
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                out.append(sorted(comp))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
    return out
