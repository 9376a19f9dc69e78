"""The live viser view: the map, the particles and the estimate of a watched session."""

from app.viz.view import LiveView

__all__ = ["LiveView"]
