"""Nothing in app/ imports in a circle (type-only imports included), and the view does
not reach into the demo."""

from __future__ import annotations

import ast
import graphlib
from pathlib import Path

APP = Path(__file__).resolve().parents[1] / "app"


def module_name(path: Path) -> str:
    parts = path.relative_to(APP.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_app_modules(path: Path, known: set[str]) -> set[str]:
    """Every app module ``path`` imports, anywhere in the file: lazy imports in functions
    and imports for type checking only (``if TYPE_CHECKING:``) count too, since a
    circle held together by type hints is still a circle in the design."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
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


def test_type_only_imports_count(tmp_path: Path) -> None:
    """An import under ``if TYPE_CHECKING:`` is an edge of the graph (the walk would
    miss a circle closed by one if it skipped them)."""
    module = tmp_path / "m.py"
    module.write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n"
        "    from app.service.sessions import SessionManager\n"
        "def f():\n"
        "    import app.maps.model\n",
        encoding="utf-8",
    )
    known = {"app.service.sessions", "app.maps.model", "app.api"}
    assert imported_app_modules(module, known) == {"app.service.sessions", "app.maps.model"}


def test_view_is_given_the_demo_rather_than_importing_it() -> None:
    graph = import_graph()
    for name, imports in graph.items():
        if name.startswith("app.viz"):
            assert "app.demo" not in imports, name
            assert not any(i.startswith(("app.api", "app.main")) for i in imports), name
