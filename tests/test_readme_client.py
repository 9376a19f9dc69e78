"""The README's phone client, run as written against a real server."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from app.config import Settings
from app.main import create_app
from tests.helpers import free_port, make_settings, serving

README = Path(__file__).resolve().parents[1] / "README.md"


def _client_code() -> str:
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## From a phone") :]
    found = re.search(r"```python\n(.*?)```", section, re.S)
    assert found, "the README's phone section has no Python example"
    return found.group(1)


def test_the_readme_client_prints_guidance(capsys: pytest.CaptureFixture[str]) -> None:
    code = _client_code()
    assert 'SERVER = "127.0.0.1:8000"' in code
    port = free_port()
    # The service's own default particle count, as the README's reader would run it.
    settings = make_settings(port=port, default_particles=Settings().default_particles)
    with serving(create_app(settings), port) as url:
        exec(compile(code.replace("127.0.0.1:8000", url), "README.md", "exec"), {})
    out = capsys.readouterr().out
    assert "Finding where you are before guiding you." in out
    assert "main entrance:" in out and "m to walk" in out
    assert "Main entrance: go to" in out
