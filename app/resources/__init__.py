"""Files shipped inside the package: the bundled maps and the demo page.

Found through :mod:`importlib.resources`, so they are where the installed package is
(a wheel, an editable install or a source checkout alike), never relative to the
working directory.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path


def _directory(name: str) -> Path:
    """A resource folder of this package as a real directory on disk."""
    folder = files(__name__).joinpath(name)
    if not isinstance(folder, Path):
        # Loading from a zip archive: the server needs real files (StaticFiles, globbing).
        raise RuntimeError(
            f"bearings' {name}/ is not on the file system ({folder!r}): install the "
            "package as files (pip install), not as a zip archive"
        )
    return folder


def bundled_maps_dir() -> Path:
    """The folder of map files shipped with Bearings (``app/resources/maps``)."""
    return _directory("maps")


def static_dir() -> Path:
    """The folder of the accessible demo page served at ``/`` (``app/resources/static``)."""
    return _directory("static")
