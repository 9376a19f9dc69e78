"""405 for an API path asked with a method it does not have, with an ``Allow`` header.

Without this, the demo page's static files, mounted at ``/``, would take such a request
(e.g. ``PUT /sessions``) and answer for themselves (``Allow: GET, HEAD``), which is
wrong for the API path.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence

from fastapi import APIRouter
from fastapi.routing import APIRoute
from starlette.types import ASGIApp, Receive, Scope, Send


class AllowedMethods:
    """Pure ASGI middleware: answers 405 with the path's real methods in ``Allow``."""

    def __init__(self, app: ASGIApp, routers: Sequence[APIRouter]) -> None:
        self.app = app
        self.routers = routers
        self._table: list[tuple[re.Pattern[str], set[str]]] | None = None

    def allowed(self, path: str) -> set[str]:
        """The documented methods of the API path that matches (empty: not an API path).

        From the same routes the OpenAPI document is made of (those in the schema), so
        ``Allow`` says exactly what the API declares, without building that document
        (a tenth of a second) on a server's first request.
        """
        if self._table is None:
            self._table = [
                (route.path_regex, {m.upper() for m in route.methods or ()})
                for router in self.routers
                for route in router.routes
                if isinstance(route, APIRoute) and route.include_in_schema
            ]
        methods: set[str] = set()
        for pattern, declared in self._table:
            if pattern.match(path):
                methods |= declared
        return methods

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            allowed = self.allowed(scope["path"])
            if allowed and scope["method"] not in allowed:
                await self._refuse(scope["method"], allowed, send)
                return
        await self.app(scope, receive, send)

    @staticmethod
    async def _refuse(method: str, allowed: set[str], send: Send) -> None:
        methods = ", ".join(sorted(allowed))
        text = f"method {method} is not allowed here; allowed: {methods}"
        await send(
            {
                "type": "http.response.start",
                "status": 405,
                "headers": [
                    (b"content-type", b"application/json"),
                    (b"allow", methods.encode()),
                ],
            }
        )
        body = json.dumps({"detail": text, "message": text}).encode()
        await send({"type": "http.response.body", "body": body})
