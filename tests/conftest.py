"""Shared by every test: prepared-map grids are cached in a temporary directory."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

import pytest

# Before any Settings is built: tests never write to the user's ~/.cache. The process
# that makes the directory removes it when it exits (pytest-xdist's workers and the
# servers the tests start inherit the variable and share it).
if "BEARINGS_CACHE_DIR" not in os.environ:
    os.environ["BEARINGS_CACHE_DIR"] = tempfile.mkdtemp(prefix="bearings-test-cache-")
    atexit.register(shutil.rmtree, os.environ["BEARINGS_CACHE_DIR"], ignore_errors=True)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests marked ``ci`` run in CI (CI=true) or with BEARINGS_ALL_TESTS=1, else skip."""
    if os.environ.get("CI") or os.environ.get("BEARINGS_ALL_TESTS"):
        return
    skip = pytest.mark.skip(reason="runs in CI (CI=true) or with BEARINGS_ALL_TESTS=1")
    for item in items:
        if "ci" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels() -> None:
    """Compile (or load from the disk cache) every numba kernel once, before any test.

    On a fresh clone the cache is empty and compiling takes a while on a busy machine;
    done here, no test's server start-up (which warms up too) waits for the compiler,
    whichever test runs first.
    """
    from app.localization.filter import warm_up

    warm_up()
