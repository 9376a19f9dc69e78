"""Liveness, and whether the worker is degraded."""

from __future__ import annotations

from fastapi import APIRouter, Request

from app.api.schemas import Health

router = APIRouter(tags=["health"])


@router.get(
    "/healthz",
    summary="Liveness probe (200 while the worker answers; degraded says what fails)",
    response_model=Health,
    response_model_exclude_defaults=True,
)
async def healthz(request: Request) -> Health:
    # (the manager is made at start-up: a probe during it sees a worker not yet degraded)
    manager = getattr(request.app.state, "manager", None)
    sharing = None if manager is None else manager.sharing
    reason = None if sharing is None else sharing.degraded()
    if reason is None:
        return Health(status="ok")
    return Health(status="degraded", reasons=[reason])
