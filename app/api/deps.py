"""Dependencies shared by the routes, as ``Annotated`` aliases.

Each is ``async``: FastAPI runs a plain ``def`` dependency in its thread pool, a thread
hop per request (and, on a server's first request, anyio's thread machinery to import)
for what is an attribute lookup.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from app.config import Settings
from app.service.metrics import Metrics
from app.service.sessions import SessionManager


async def get_manager(request: Request) -> SessionManager:
    return request.app.state.manager


async def get_app_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_metrics(request: Request) -> Metrics:
    return request.app.state.metrics


ManagerDep = Annotated[SessionManager, Depends(get_manager)]
SettingsDep = Annotated[Settings, Depends(get_app_settings)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]
