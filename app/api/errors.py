"""Error answers: always a status that fits and a body that says what was wrong."""

from __future__ import annotations

import math
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
from app.service.errors import (
    CapacityReached,
    InvalidSessionSpec,
    LimitReached,
    QuotaReached,
    RequestTooLarge,
    SessionNotFound,
    SessionUnavailable,
    UnknownMap,
)
from app.validation import problem_text

#: The HTTP status of each service limit: the service says what was hit, the API
#: decides how HTTP says it. A client's own quota is 429, the whole service full (or
#: restarting) is 503, a request larger than ever allowed is 422.
LIMIT_STATUS: dict[type[LimitReached], int] = {
    QuotaReached: 429,
    CapacityReached: 503,
    SessionUnavailable: 503,
    RequestTooLarge: 422,
}


def limit_status(exc: LimitReached) -> int:
    """The status for a service limit (see :data:`LIMIT_STATUS`; 429 for any other)."""
    for kind, status in LIMIT_STATUS.items():
        if isinstance(exc, kind):
            return status
    return 429


#: What each error status means on this API (docs/API.md, "Errors"); every one of them
#: answers with an :class:`~app.api.schemas.ErrorBody`.
ERROR_MEANING: dict[int, str] = {
    400: "the request cannot be read (e.g. a body that is not UTF-8)",
    401: "the service needs an API key and the request has none or a wrong one "
    "('Authorization: Bearer KEY'; only when the service is configured with keys)",
    404: "no such session or map (the message lists the known maps)",
    413: "the request body is larger than the service's limit",
    422: "the body fails validation (the message says which field and why), asks for "
    "more than a limit allows (code too_many_particles, too_many_detections), puts "
    "the initial pose outside the map's free space, gives a pixel box the session's "
    "camera cannot read (no camera, outside the image), or names a destination that is "
    "unknown or cannot be reached",
    429: "this API key's quota is used up right now (code session_quota, particle_quota "
    "or rate_limited): try again after Retry-After seconds",
    503: "the service is full or stopping (code too_many_sessions, busy, restarting: try "
    "again after Retry-After seconds), or the feature needs something the machine lacks "
    "(no speech engine)",
}


def error_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries for a route's error statuses, all with ErrorBody."""
    return {s: {"model": ErrorBody, "description": ERROR_MEANING[s]} for s in statuses}


def retry_after(exc: LimitReached) -> str | None:
    """The ``Retry-After`` header value (whole seconds, at least 1), or None."""
    if exc.retry_after_s is None:
        return None
    return str(max(1, math.ceil(exc.retry_after_s)))


def limit_body(exc: LimitReached) -> dict[str, object]:
    """What a refused request is told (HTTP body, or the WebSocket error's fields)."""
    body: dict[str, object] = {"code": exc.code, "message": str(exc)}
    if exc.retry_after_s is not None:
        body["retry_after_s"] = round(max(exc.retry_after_s, 0.0), 3)
    return body


def document_key_errors(app: FastAPI, open_paths: frozenset[str]) -> None:
    """Declare 401 on every operation outside ``open_paths`` (the API-key check, done by
    middleware, answers it before any route runs)."""
    build = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = build()
            body = {"$ref": "#/components/schemas/ErrorBody"}
            for path, operations in schema.get("paths", {}).items():
                if path in open_paths:
                    continue
                for op in operations.values():
                    op["responses"].setdefault(
                        "401",
                        {
                            "description": ERROR_MEANING[401],
                            "content": {"application/json": {"schema": body}},
                        },
                    )
        return app.openapi_schema or build()

    app.openapi = openapi  # type: ignore[method-assign]  # FastAPI's documented override


def describe_validation(errors: Sequence[Mapping[str, Any]]) -> str:
    """One readable sentence per problem: 'detections.0.score: must be <= 1'."""
    parts = []
    for e in errors:
        loc = [str(p) for p in e.get("loc", ()) if p not in ("body",)]
        where = ".".join(loc) or "body"
        parts.append(f"{where}: {problem_text(e)}")
    return "; ".join(parts)


def _plain(errors: list[dict]) -> list[dict]:
    # Drop the 'ctx'/'input' parts that may hold non-JSON values (e.g. NaN, exceptions).
    return [
        {"type": e.get("type"), "loc": e.get("loc", ()), "msg": problem_text(e)} for e in errors
    ]


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
        after = retry_after(exc)
        return JSONResponse(
            status_code=limit_status(exc),
            content={"detail": str(exc), **limit_body(exc)},
            headers=None if after is None else {"Retry-After": after},
        )
