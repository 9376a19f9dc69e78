"""Where the bundled maps and the demo page are: ``maps/`` and ``static/``.

Both folders sit at the top of the repository, beside ``app/``, and exist only there.
The wheel ships them inside the package, as ``app/resources/maps`` and
``app/resources/static`` (``force-include`` in pyproject.toml), so a regular install
finds them next to this module through :mod:`importlib.resources`, whatever the working
directory. An editable install and a source checkout (the tests) import ``app`` from the
checkout, where no such copy exists: there the folders are the checkout's own.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

#: The repository's root when ``app`` is imported from a checkout (editable install,
#: tests): the folder holding ``app/`` and ``pyproject.toml``.
_CHECKOUT = Path(__file__).resolve().parents[2]


def _directory(name: str) -> Path:
    """The folder ``name`` as a real directory: the installed package's copy, else the
    checkout's.

    Raises:
        RuntimeError: neither exists (or the package is loaded from a zip archive, whose
            files the server cannot serve or glob).
    """
    packaged = files(__name__).joinpath(name)
    if not isinstance(packaged, Path):
        raise RuntimeError(
            f"bearings' {name}/ is not on the file system ({packaged!r}): install the "
            "package as files (pip install), not as a zip archive"
        )
    if packaged.is_dir():
        return packaged
    checkout = _CHECKOUT / name
    if checkout.is_dir() and (_CHECKOUT / "pyproject.toml").is_file():
        return checkout
    raise RuntimeError(
        f"bearings' {name}/ folder is missing: neither the installed package holds it "
        f"({packaged}) nor is this a source checkout with {name}/ beside app/ ({checkout}); "
        "reinstall the package"
    )


def bundled_maps_dir() -> Path:
    """The folder of map files shipped with Bearings (``maps/``)."""
    return _directory("maps")


def static_dir() -> Path:
    """The folder of the accessible demo page served at ``/`` (``static/``)."""
    return _directory("static")
