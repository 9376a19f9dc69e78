"""The wheel works installed, not only from a checkout.

Builds the wheel from pyproject.toml, installs it into a fresh virtual environment
and runs ``bearings serve`` from an unrelated directory: the bundled maps and the
demo page must come from the installed package. To stay fast the venv borrows the
already installed dependencies (a path file pointing at this interpreter's
site-packages, which, unlike ``--system-site-packages``, also works when the tests run
inside a venv); the package itself is only the wheel's copy.
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

from app.resources import bundled_maps_dir
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
    assert not any(n.startswith(("tests/", "benchmarks/")) for n in names)


def get(url: str) -> tuple[int, bytes]:
    with urllib.request.urlopen(url, timeout=5) as r:
        return r.status, r.read()


@pytest.mark.ci  # about 80 s: a fresh install compiles every kernel into an empty cache
def test_installed_wheel_serves_bundled_maps_and_the_demo_page(wheel: Path, tmp_path: Path) -> None:
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
    pip = [sys.executable, "-m", "pip", "--python", str(python)]
    subprocess.run(
        [*pip, "install", "-q", "--no-deps", str(wheel)],
        check=True,
        timeout=300,
        capture_output=True,
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba-cache")
    where = subprocess.run(
        [str(python), "-c", "import app; print(app.__file__)"],
        cwd=elsewhere,
        env=env,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    assert Path(where).is_relative_to(venv), f"imported the checkout, not the wheel: {where}"

    port = free_port()
    log = (tmp_path / "serve.log").open("w")
    server = subprocess.Popen(
        [str(venv / "bin" / "bearings"), "serve", "--no-viser", "--port", str(port)],
        cwd=elsewhere,
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.time() + 240  # start-up compiles the kernels into an empty cache
        while True:
            assert server.poll() is None, (tmp_path / "serve.log").read_text()
            try:
                status, body = get(f"http://127.0.0.1:{port}/maps")
                break
            except (urllib.error.URLError, ConnectionError):
                assert time.time() < deadline, "the installed server did not start"
                time.sleep(0.5)
        assert status == 200
        served = {m["name"] for m in json.loads(body)}
        assert {p.stem for p in bundled_maps_dir().glob("*.json")} <= served
        status, page = get(f"http://127.0.0.1:{port}/")
        assert status == 200
        assert page == (bundled_maps_dir().parent / "static" / "index.html").read_bytes()
    finally:
        server.terminate()
        server.wait(timeout=30)
        log.close()
