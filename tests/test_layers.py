"""Every arrow points down: data/ reads and preprocesses recordings and imports nothing above it; the runner and
the report of experiments/ do not import each other."""

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "reachirl"


def imported_modules(path: Path) -> set[str]:
    """Absolute module names ``path`` imports (relative imports resolved), at any depth of the file."""
    package = ".".join(("reachirl", *path.relative_to(SRC).parent.parts))
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")
            if node.level:
                base = base[: len(base) - node.level + 1]
                mod = ".".join([*base, node.module] if node.module else base)
            else:
                mod = node.module or ""
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return out


def test_data_imports_nothing_from_the_doc_irl_experiments_or_sim():
    for f in sorted((SRC / "data").rglob("*.py")):
        bad = {m for m in imported_modules(f)
               if m.split(".")[:2] in (["reachirl", "doc"], ["reachirl", "irl"], ["reachirl", "experiments"],
                                       ["reachirl", "sim"], ["reachirl", "synth"], ["reachirl", "evaluation"])}
        assert not bad, f"{f.relative_to(SRC)} imports {sorted(bad)}"


def test_runner_and_report_do_not_import_each_other():
    runner = imported_modules(SRC / "experiments" / "runner.py")
    report = imported_modules(SRC / "experiments" / "report.py")
    assert not any(m.startswith("reachirl.experiments.report") for m in runner)
    assert not any(m.startswith("reachirl.experiments.runner") for m in report)


def test_the_resolver_sees_relative_imports():
    assert "reachirl.doc.task.ReachingTask" in imported_modules(SRC / "doc" / "__init__.py") or \
        "reachirl.doc.task" in imported_modules(SRC / "doc" / "__init__.py")
    assert "reachirl.data.trial" in imported_modules(SRC / "evaluation.py")
