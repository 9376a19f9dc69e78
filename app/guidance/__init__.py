"""Guidance to a destination: shortest walkable paths and what to tell the person.

Depends only on the map model (app.maps.model): :mod:`~app.guidance.targets`
resolves what was asked for, :mod:`~app.guidance.planner` plans the walk once per map
and target (across levels through :mod:`~app.guidance.levels`),
:mod:`~app.guidance.guide` turns a pose and a plan into directions.
"""

from app.guidance.guide import ARRIVED_M, ConnectorStep, Guidance, NextTurn, guide
from app.guidance.planner import Plan, Route, Unreachable, plan_for
from app.guidance.targets import DestinationSpec, Target, UnknownDestination, resolve

__all__ = [
    "ARRIVED_M",
    "ConnectorStep",
    "DestinationSpec",
    "Guidance",
    "NextTurn",
    "Plan",
    "Route",
    "Target",
    "UnknownDestination",
    "Unreachable",
    "guide",
    "plan_for",
    "resolve",
]
