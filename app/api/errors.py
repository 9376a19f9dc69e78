"""Error answers: always a status that fits and a body that says what was wrong."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.api.schemas import ErrorBody
from app.guidance import UnknownDestination, Unreachable
from app.localization.camera import BoxError
from app.service.sessions import (
    CapacityReached,
    InvalidSessionSpec,
    LimitReached,
    RequestTooLarge,
    SessionNotFound,
    UnknownMap,
)

#: The HTTP status of each service limit: the service says what was hit, the API
#: decides how HTTP says it.
LIMIT_STATUS: dict[type[LimitReached], int] = {CapacityReached: 429, RequestTooLarge: 422}


def limit_status(exc: LimitReached) -> int:
    """The status for a service limit (429 for capacity, 422 for an oversized request)."""
    for kind, status in LIMIT_STATUS.items():
        if isinstance(exc, kind):
            return status
    return 429


#: What each error status means on this API (docs/API.md, "Errors"); every one of them
#: answers with an :class:`~app.api.schemas.ErrorBody`.
ERROR_MEANING: dict[int, str] = {
    400: "the request cannot be read (e.g. a body that is not UTF-8)",
    404: "no such session or map (the message lists the known maps)",
    413: "the request body is larger than the service's limit",
    422: "the body fails validation (the message says which field and why), asks for "
    "more than a limit allows (code too_many_particles, too_many_detections), puts "
    "the initial pose outside the map's free space, gives a pixel box the session's "
    "camera cannot read (no camera, outside the image), or names a destination that is "
    "unknown or cannot be reached",
    429: "the service is at capacity (code too_many_sessions): try again later",
    503: "the feature needs something the machine lacks (no speech engine)",
}


def error_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries for a route's error statuses, all with ErrorBody."""
    return {s: {"model": ErrorBody, "description": ERROR_MEANING[s]} for s in statuses}


def describe_validation(errors: Sequence[Mapping[str, Any]]) -> str:
    """One readable sentence per problem: 'detections.0.score: must be <= 1'."""
    parts = []
    for e in errors:
        loc = [str(p) for p in e.get("loc", ()) if p not in ("body",)]
        where = ".".join(loc) or "body"
        parts.append(f"{where}: {e.get('msg', 'invalid')}")
    return "; ".join(parts)


def _plain(errors: list[dict]) -> list[dict]:
    # Drop the 'ctx'/'input' parts that may hold non-JSON values (e.g. NaN, exceptions).
    return [{k: v for k, v in e.items() if k in ("type", "loc", "msg")} for e in errors]


async def _validation(_: Request, exc: Exception) -> JSONResponse:
    """422 for a request body (or a model built from it) that fails validation."""
    assert isinstance(exc, RequestValidationError | ValidationError)
    errors = list(exc.errors())
    return JSONResponse(
        status_code=422,
        content={"detail": _plain(errors), "message": describe_validation(errors)},
    )


def install_error_handlers(app: FastAPI) -> None:
    app.add_exception_handler(RequestValidationError, _validation)
    app.add_exception_handler(ValidationError, _validation)

    @app.exception_handler(StarletteHTTPException)
    async def _http(_: Request, exc: StarletteHTTPException) -> JSONResponse:
        return JSONResponse(
            status_code=exc.status_code,
            content={"detail": exc.detail, "message": str(exc.detail)},
            headers=getattr(exc, "headers", None),
        )

    @app.exception_handler(SessionNotFound)
    async def _missing(_: Request, exc: SessionNotFound) -> JSONResponse:
        return JSONResponse(
            status_code=404, content={"detail": exc.message, "message": exc.message}
        )

    @app.exception_handler(UnknownMap)
    async def _unknown_map(_: Request, exc: UnknownMap) -> JSONResponse:
        return JSONResponse(status_code=404, content={"detail": str(exc), "message": str(exc)})

    @app.exception_handler(InvalidSessionSpec)
    async def _invalid_spec(_: Request, exc: InvalidSessionSpec) -> JSONResponse:
        return JSONResponse(status_code=422, content={"detail": str(exc), "message": str(exc)})

    @app.exception_handler(BoxError)
    @app.exception_handler(UnknownDestination)
    @app.exception_handler(Unreachable)
    async def _unusable(_: Request, exc: Exception) -> JSONResponse:
        """A box the session's camera cannot read, or a destination it cannot guide to."""
        return JSONResponse(status_code=422, content={"detail": str(exc), "message": str(exc)})

    @app.exception_handler(LimitReached)
    async def _limit(_: Request, exc: LimitReached) -> JSONResponse:
        return JSONResponse(
            status_code=limit_status(exc),
            content={"detail": str(exc), "message": str(exc), "code": exc.code},
        )
