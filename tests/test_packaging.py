"""Both install kinds serve the bundled maps and the demo page.

The maps and the page live at the top of the repository (``maps/``, ``static/``); the
wheel carries them inside the package. Builds the wheel from pyproject.toml, installs it
into a fresh virtual environment and runs ``bearings serve`` from an unrelated
directory: the maps and the page must come from the installed package. An editable
install into another fresh venv must serve the checkout's own folders. To stay fast
each venv borrows the already installed dependencies (a path file pointing at this
interpreter's site-packages, which, unlike ``--system-site-packages``, also works when
the tests run inside a venv); the package itself is only the wheel's copy or the
checkout.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import time
import urllib.error
import urllib.request
import zipfile
from pathlib import Path

import pytest

from app.resources import bundled_maps_dir, static_dir
from tests.helpers import free_port

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(ROOT)],
        check=True,
        timeout=300,
        capture_output=True,
    )
    (built,) = out.glob("bearings-*.whl")
    return built


def test_wheel_holds_the_resources_the_type_marker_and_the_licence(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    bundled = {p.name for p in bundled_maps_dir().glob("*.json")}
    assert bundled and {f"app/resources/maps/{n}" for n in bundled} <= names
    assert "app/resources/static/index.html" in names
    assert "app/py.typed" in names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert not any(n.startswith(("tests/", "benchmarks/", "maps/", "static/")) for n in names)


def get(url: str) -> tuple[int, bytes]:
    with urllib.request.urlopen(url, timeout=5) as r:
        return r.status, r.read()


def fresh_venv(tmp_path: Path) -> Path:
    """A venv without pip that sees this interpreter's dependencies; its python."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
    )
    # The dependencies from this interpreter (plain path lines: its .pth files, such as
    # an editable install of this checkout, are not processed).
    paths = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "_bearings_test_deps.pth").write_text("\n".join(sorted(paths)) + "\n")
    return python


def install(python: Path, *args: str) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", *args],
        check=True,
        timeout=300,
        capture_output=True,
    )


def run_python(python: Path, code: str, cwd: Path, env: dict[str, str]) -> str:
    done = subprocess.run(
        [str(python), "-c", code], cwd=cwd, env=env, check=True, capture_output=True, text=True
    )
    return done.stdout.strip()


def serves_maps_and_page(bearings: Path, cwd: Path, env: dict[str, str], log_path: Path) -> None:
    """Start ``bearings serve`` there; every bundled map is listed and / is the page."""
    port = free_port()
    log = log_path.open("w")
    server = subprocess.Popen(
        [str(bearings), "serve", "--no-viser", "--port", str(port)],
        cwd=cwd,
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.time() + 240  # start-up may compile the kernels into an empty cache
        while True:
            assert server.poll() is None, log_path.read_text()
            try:
                status, body = get(f"http://127.0.0.1:{port}/maps")
                break
            except (urllib.error.URLError, ConnectionError):
                assert time.time() < deadline, "the installed server did not start"
                time.sleep(0.5)
        assert status == 200
        served = {m["name"] for m in json.loads(body)}
        assert {p.stem for p in (ROOT / "maps").glob("*.json")} <= served
        status, page = get(f"http://127.0.0.1:{port}/")
        assert status == 200
        assert page == (ROOT / "static" / "index.html").read_bytes()
    finally:
        server.terminate()
        server.wait(timeout=30)
        log.close()


def clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return {**env, **extra}


def test_a_checkout_finds_the_top_level_folders() -> None:
    """No copy inside app/: the tests (a checkout) read maps/ and static/ themselves."""
    assert bundled_maps_dir() == ROOT / "maps" and static_dir() == ROOT / "static"
    assert not (ROOT / "app" / "resources" / "maps").exists()
    assert not (ROOT / "app" / "resources" / "static").exists()


@pytest.mark.ci  # about 80 s: a fresh install compiles every kernel into an empty cache
def test_installed_wheel_serves_bundled_maps_and_the_demo_page(wheel: Path, tmp_path: Path) -> None:
    python = fresh_venv(tmp_path)
    install(python, str(wheel))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = clean_env(NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    where = run_python(python, "import app; print(app.__file__)", elsewhere, env)
    assert Path(where).is_relative_to(tmp_path / "venv"), f"imported the checkout: {where}"
    folders = run_python(
        python,
        "from app.resources import bundled_maps_dir as m, static_dir as s; print(m(), s())",
        elsewhere,
        env,
    )
    site_app = Path(where).parent
    assert folders == f"{site_app / 'resources' / 'maps'} {site_app / 'resources' / 'static'}"
    serves_maps_and_page(python.parent / "bearings", elsewhere, env, tmp_path / "serve.log")


@pytest.mark.ci  # builds an editable wheel in an isolated environment (hatchling from PyPI)
def test_editable_install_serves_the_checkouts_maps_and_page(tmp_path: Path) -> None:
    """An editable install has no copy of the folders (force-include does not reach it):
    app/resources finds the checkout's own, and the server serves them."""
    python = fresh_venv(tmp_path)
    install(python, "-e", str(ROOT))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = clean_env()  # the checkout's numba cache: the kernels are compiled already
    where = run_python(python, "import app; print(app.__file__)", elsewhere, env)
    assert Path(where) == ROOT / "app" / "__init__.py", f"not the checkout: {where}"
    folders = run_python(
        python,
        "from app.resources import bundled_maps_dir as m, static_dir as s; print(m(), s())",
        elsewhere,
        env,
    )
    assert folders == f"{ROOT / 'maps'} {ROOT / 'static'}"
    serves_maps_and_page(python.parent / "bearings", elsewhere, env, tmp_path / "serve.log")
