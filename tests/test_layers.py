"""The package's import graph: no module imports itself through others (no cycle), and every arrow points down
the layers, base → data → doc → irl → experiments → cli, with virtual subjects and MuJoCo playback beside irl
above doc. Every import counts: at module level and inside functions, absolute and relative."""

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "reachirl"

#: the layers, lowest first: a module may import its own layer and those listed below it in ``MAY_IMPORT``
LAYERS = {
    "base": (
        "reachirl.errors",
        "reachirl.io",
        "reachirl.validation",
        "reachirl.arm",
        "reachirl.features",
        "reachirl.workers",
    ),
    "data": ("reachirl.data",),
    "doc": ("reachirl.doc",),
    "irl": ("reachirl.irl",),
    "synth": ("reachirl.virtual",),
    "sim": ("reachirl.sim",),
    "experiments": ("reachirl.experiments",),
    "cli": ("reachirl.cli", "reachirl.__main__"),
}
API = "reachirl"  # the package's face: names handed on from the layers, imported by none of them
MAY_IMPORT = {
    "base": {"base"},
    "data": {"base", "data"},
    "doc": {"base", "data", "doc"},
    "irl": {"base", "data", "doc", "irl"},
    "synth": {"base", "data", "doc", "synth"},
    "sim": {"base", "data", "doc", "sim"},
    "experiments": {"base", "data", "doc", "irl", "synth", "experiments"},
    "cli": {"base", "data", "doc", "irl", "synth", "sim", "experiments", "cli", API},
    API: {"base", "data", "doc", "irl"},
}


def module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(SRC.rglob("*.py"))}


def imported_modules(path: Path) -> set[str]:
    """The package's modules that ``path`` imports anywhere in the file (relative imports resolved; ``from P
    import x`` is an import of the module ``P.x`` when there is one, else of ``P``)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join([*base, node.module] if node.module else base)
            else:
                mod = node.module or ""
            out |= {f"{mod}.{a.name}" if f"{mod}.{a.name}" in MODULES else mod for a in node.names}
    return {m for m in out if m in MODULES and m != name}


def import_graph() -> dict[str, set[str]]:
    return {name: imported_modules(path) for name, path in MODULES.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def layer(module: str) -> str | None:
    """The layer of ``module`` (None when it has none): the one whose prefix matches it longest; the package's
    ``__init__`` is its own layer, :data:`API`."""
    if module == API:
        return API
    best, length = None, -1
    for name, prefixes in LAYERS.items():
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > length:
                best, length = name, len(p)
    return best


def test_the_package_has_no_import_cycle():
    assert cycles(import_graph()) == []


def test_every_import_points_down_the_layers():
    wrong = sorted(
        f"{m} ({layer(m)}) imports {d} ({layer(d)})"
        for m, deps in import_graph().items()
        for d in deps
        if layer(d) not in MAY_IMPORT[layer(m)]
    )
    assert wrong == []


def test_every_module_has_a_layer():
    assert [m for m in MODULES if layer(m) is None] == []


def test_the_cycle_finder_finds_each_cycle_and_nothing_else():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a", "e"}, "e": {"d"}, "f": {"a"}}
    assert sorted(cycles(graph)) == [["a", "b", "c"], ["d", "e"]]
    assert cycles({"a": {"b"}, "b": set(), "c": {"a", "b"}}) == []


@pytest.mark.parametrize(
    ("module", "imports"),
    [
        ("reachirl.doc.evaluation", "reachirl.data.trial"),  # ``from ..data.trial import Trial``
        ("reachirl.doc", "reachirl.doc.task"),  # ``from .task import …`` in a package's __init__
        ("reachirl.io", "reachirl.errors"),  # ``from .errors import InputError`` inside a function
        ("reachirl.cli.plot", "reachirl.experiments.figures"),  # ``from ..experiments import figures`` (a module)
    ],
)
def test_the_graph_sees_every_kind_of_import(module, imports):
    assert imports in import_graph()[module]


def test_runner_and_report_do_not_import_each_other():
    graph = import_graph()
    assert "reachirl.experiments.report" not in graph["reachirl.experiments.runner"]
    assert "reachirl.experiments.runner" not in graph["reachirl.experiments.report"]
