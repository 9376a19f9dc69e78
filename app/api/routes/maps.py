"""The maps the service knows."""

from __future__ import annotations

from fastapi import APIRouter

from app.api.deps import ManagerDep
from app.api.errors import error_responses
from app.api.schemas import Bounds, MapSummary
from app.service.errors import UnknownMap

router = APIRouter(prefix="/maps", tags=["maps"])


@router.get("", response_model=list[MapSummary], summary="List the maps")
async def list_maps(manager: ManagerDep) -> list[MapSummary]:
    out = []
    for m in manager.maps.values():
        x0, y0, x1, y1 = m.bounds
        out.append(
            MapSummary(
                name=m.name,
                description=m.description,
                classes=list(m.classes),
                object_count=m.object_count,
                bounds=Bounds(min_x=x0, min_y=y0, max_x=x1, max_y=y1),
            )
        )
    return out


@router.get("/{name}", summary="One map file's JSON", responses=error_responses(404))
async def get_map(name: str, manager: ManagerDep) -> dict[str, object]:
    if name not in manager.maps:
        raise UnknownMap(name, sorted(manager.maps))
    return manager.maps[name].to_json()
