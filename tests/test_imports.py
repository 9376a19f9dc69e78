"""Nothing in app/ imports in a circle, and the view does not reach into the demo."""

from __future__ import annotations

import ast
import graphlib
from pathlib import Path

APP = Path(__file__).resolve().parents[1] / "app"


def module_name(path: Path) -> str:
    parts = path.relative_to(APP.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def runtime_nodes(tree: ast.AST) -> list[ast.AST]:
    """Every node except those under ``if TYPE_CHECKING:`` (never executed)."""
    out: list[ast.AST] = []
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            stack.extend(node.orelse)
            continue
        out.append(node)
        stack.extend(ast.iter_child_nodes(node))
    return out


def imported_app_modules(path: Path, known: set[str]) -> set[str]:
    """Every app module ``path`` imports when it runs, anywhere in the file (lazy imports
    in functions too); imports for type checking only are not counted."""
    found: set[str] = set()
    for node in runtime_nodes(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name in known)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module in known:
                found.add(node.module)
            # ``from app.api.routes import demo`` imports the module app.api.routes.demo.
            found |= {f"{node.module}.{a.name}" for a in node.names} & known
    return found


def import_graph() -> dict[str, set[str]]:
    paths = sorted(APP.rglob("*.py"))
    known = {module_name(p) for p in paths}
    return {module_name(p): imported_app_modules(p, known) - {module_name(p)} for p in paths}


def test_no_module_of_app_imports_in_a_circle() -> None:
    graph = import_graph()
    assert len(graph) > 40  # the walk found the package
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        raise AssertionError(f"import cycle: {' -> '.join(exc.args[1])}") from None


def test_view_is_given_the_demo_rather_than_importing_it() -> None:
    graph = import_graph()
    for name, imports in graph.items():
        if name.startswith("app.viz"):
            assert "app.demo" not in imports, name
            assert not any(i.startswith(("app.api", "app.main")) for i in imports), name
