"""Shared by every test: prepared-map grids are cached in a temporary directory."""

from __future__ import annotations

import os
import tempfile

# Before any Settings is built: tests never write to the user's ~/.cache.
os.environ.setdefault("BEARINGS_CACHE_DIR", tempfile.mkdtemp(prefix="bearings-test-cache-"))
