"""The floor plan as data: the map model, its geometry, checks, importers and prepared grids.

Everything here stands on its own; :mod:`app.localization` imports from it, never the
reverse.
"""
