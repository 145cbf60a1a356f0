"""The package layout of issues #13 and #26 (docs/architecture.md), checked on the source: no import
cycle between graphnav modules (function-level, lazy imports included), no module importing a higher
layer (kernel < io < scan/sim/beacons < graph < estimators < evaluation/online < commands), no library
module importing the CLI layer, unique module names, at most 10 modules at the top level."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "graphnav"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """Module -> the graphnav modules it imports anywhere in its source (``from P import m`` with
    ``P.m`` a module counts as importing ``P.m``; importing a package counts its ``__init__``)."""
    files = {module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for mod, path in files.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        edges: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    src = ".".join(base + ([node.module] if node.module else []))
                else:
                    src = node.module or ""
                targets = [src] + [f"{src}.{a.name}" for a in node.names]
            else:
                continue
            edges |= {t for t in targets if t in files and t != mod}
        graph[mod] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
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
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle():
    assert cycles(import_graph()) == []


#: the layers, lowest first: a module may import its own layer and the ones below, never one above
LAYERS = (("kernel",), ("io",), ("scan", "sim", "beacons"), ("graph",), ("estimators",), ("evaluation", "online"),
          ("commands", "cli", "__main__"))


def layer(mod: str) -> int:
    """The layer of a graphnav module: a top-level module (``graphnav.log``, ...) is the kernel, a
    package's modules are that package's layer."""
    top = mod.split(".")[1]
    found = [i for i, names in enumerate(LAYERS) if top in names]
    return found[0] if found else 0  # a top-level module: the kernel


def upward_imports(graph: dict[str, set[str]]) -> dict[str, list[str]]:
    """Module -> the modules of a higher layer it imports. Importing an enclosing package (``from .. import
    estimators`` runs ``graphnav/__init__``, the lazy top-level API) is not an edge: it has already run."""
    out: dict[str, list[str]] = {}
    for mod, edges in graph.items():
        if mod == "graphnav":
            continue
        up = sorted(e for e in edges if not mod.startswith(e + ".") and layer(e) > layer(mod))
        if up:
            out[mod] = up
    return out


def test_layer_finder_finds_an_upward_import():
    assert layer("graphnav.trajectory") == 0 and layer("graphnav.io.tum") == 1 and layer("graphnav.io") == 1
    assert layer("graphnav.sim.harbour") == layer("graphnav.beacons.layout") == 2
    assert layer("graphnav.commands.run") == layer("graphnav.cli") == 6
    graph = {"graphnav.trajectory": {"graphnav.io.outputs"}, "graphnav.io.outputs": set(),
             "graphnav.online.live_runner": {"graphnav", "graphnav.graph.navigator"}}
    assert upward_imports(graph) == {"graphnav.trajectory": ["graphnav.io.outputs"]}


def test_no_import_from_a_higher_layer():
    assert upward_imports(import_graph()) == {}


def test_library_does_not_import_the_cli():
    cli = ("graphnav.commands", "graphnav.cli", "graphnav.__main__")
    bad = {m: sorted(e for e in edges if e.startswith(cli))
           for m, edges in import_graph().items() if not m.startswith(cli)}
    assert {m: e for m, e in bad.items() if e} == {}


def test_top_level_has_at_most_ten_modules():
    top = sorted(p.name for p in PKG.glob("*.py"))
    assert len(top) <= 10, top


def test_module_names_are_unique():
    """No two modules share a file name (``__init__`` aside), across graphnav and factors (issue #26)."""
    names: dict[str, list[str]] = {}
    for root in (PKG, PKG.parent / "factors"):
        for p in root.rglob("*.py"):
            if p.name != "__init__.py":
                names.setdefault(p.stem, []).append(str(p.relative_to(PKG.parent)))
    assert {n: ps for n, ps in names.items() if len(ps) > 1} == {}


#: classes over 300 lines or 25 attributes, functions over 80 lines, as of issue #26 (to split; no new ones).
#: Config dataclasses (one attribute per option) and the simulators' and readers' functions are exempt.
KNOWN_LARGE: set[str] = set()


def _attributes(cls: ast.ClassDef) -> set[str]:
    """``self.X`` assigned anywhere in the class, and names assigned in its body."""
    out: set[str] = set()
    for node in ast.walk(cls):
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign | ast.AugAssign) else []
        for t in targets:
            out |= {e.attr for e in ast.walk(t) if isinstance(e, ast.Attribute)
                    and isinstance(e.value, ast.Name) and e.value.id == "self"}
    for st in cls.body:
        if isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name):
            out.add(st.target.id)
        elif isinstance(st, ast.Assign):
            out |= {t.id for t in st.targets if isinstance(t, ast.Name)}
    return out


def large_parts() -> set[str]:
    """Classes over 300 lines or 25 attributes (config dataclasses aside) and functions over 80 lines
    (outside the simulators and the readers), by dotted name."""
    out: set[str] = set()
    for path in PKG.rglob("*.py"):
        mod = module_name(path)
        def visit(node: ast.AST, prefix: str, exempt_fn: bool) -> None:
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.ClassDef):
                    config = child.name.endswith(("Config", "Options"))
                    if not config and (child.end_lineno - child.lineno >= 300 or len(_attributes(child)) > 25):
                        out.add(f"{prefix}.{child.name}")
                    visit(child, f"{prefix}.{child.name}", exempt_fn)
                elif isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                    if not exempt_fn and child.end_lineno - child.lineno >= 80:
                        out.add(f"{prefix}.{child.name}")
                    visit(child, f"{prefix}.{child.name}", exempt_fn)

        visit(ast.parse(path.read_text(encoding="utf-8")), mod, mod.startswith(("graphnav.sim.", "graphnav.io.")))
    return out


def test_no_new_large_class_or_function():
    assert large_parts() - KNOWN_LARGE == set()
