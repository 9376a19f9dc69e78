"""Error answers: always a status that fits and a body that says what was wrong."""

from __future__ import annotations

import math

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.guidance import UnknownDestination, Unreachable
from app.localization.camera import BoxError
from app.service.sessions import (
    CapacityReached,
    InvalidSessionSpec,
    LimitReached,
    QuotaReached,
    RequestTooLarge,
    SessionNotFound,
    UnknownMap,
)

#: The HTTP status of each service limit: the service says what was hit, the API
#: decides how HTTP says it. A client's own quota is 429, the whole service full (or
#: restarting) is 503, a request larger than ever allowed is 422.
LIMIT_STATUS: dict[type[LimitReached], int] = {
    QuotaReached: 429,
    CapacityReached: 503,
    RequestTooLarge: 422,
}


def limit_status(exc: LimitReached) -> int:
    """The status for a service limit (see :data:`LIMIT_STATUS`; 429 for any other)."""
    for kind, status in LIMIT_STATUS.items():
        if isinstance(exc, kind):
            return status
    return 429


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


def describe_validation(errors: list[dict]) -> str:
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
    errors = list(exc.errors())  # type: ignore[attr-defined]
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
