"""The maps the service knows."""

from __future__ import annotations

from fastapi import APIRouter

from app.api.deps import ManagerDep
from app.api.errors import error_responses
from app.api.schemas import Bounds, ConnectorOut, MapLevelOut, MapSummary
from app.service.errors import UnknownMap

router = APIRouter(prefix="/maps", tags=["maps"])


@router.get("", response_model=list[MapSummary], summary="List the maps")
async def list_maps(manager: ManagerDep) -> list[MapSummary]:
    out = []
    for m in manager.maps.values():
        layout = m.layout
        # Several levels lie side by side in the filter's plane: the file's extent.
        x0, y0, x1, y1 = layout.file_bounds if layout.has_levels else m.bounds
        spec = m.spec
        out.append(
            MapSummary(
                name=m.name,
                description=m.description,
                classes=list(m.classes),
                object_count=m.object_count,
                bounds=Bounds(min_x=x0, min_y=y0, max_x=x1, max_y=y1),
                levels=[
                    MapLevelOut(
                        id=lv.id, name=lv.name, ordinal=lv.ordinal, elevation_m=lv.elevation_m
                    )
                    for lv in layout.levels
                ],
                connectors=[ConnectorOut.model_validate(c.model_dump()) for c in spec.connectors],
            )
        )
    return out


@router.get("/{name}", summary="One map file's JSON", responses=error_responses(404))
async def get_map(name: str, manager: ManagerDep) -> dict[str, object]:
    if name not in manager.maps:
        raise UnknownMap(name, sorted(manager.maps))
    return manager.maps[name].to_json()
