"""The service layer stands on its own: it imports nothing of HTTP or the API."""

from __future__ import annotations

import ast
from pathlib import Path

SERVICE = Path(__file__).resolve().parents[2] / "app" / "service"


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_service_imports_no_api_and_no_web_framework() -> None:
    modules = sorted(SERVICE.glob("*.py"))
    assert modules, "no service modules found"
    for path in modules:
        bad = {
            n
            for n in _imports(path)
            if n.startswith(("app.api", "fastapi", "starlette")) or n == "app.main"
        }
        assert not bad, f"{path.name} imports {sorted(bad)}"
