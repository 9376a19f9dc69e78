"""Who is calling: API keys on every route but ``/healthz``, and browser origins on WebSockets.

A pure ASGI middleware, so it also guards the WebSocket upgrade (refused before it is
accepted) and the static pages. It records the caller's
:class:`~app.service.access.Principal` in the connection's scope, where the routes read
it (:func:`get_principal`). docs/SECURITY.md describes the whole scheme.
"""

from __future__ import annotations

import ipaddress
import json
from typing import Annotated
from urllib.parse import parse_qsl, urlsplit

from fastapi import Depends
from starlette.requests import HTTPConnection
from starlette.types import ASGIApp, Receive, Scope, Send

from app.config import Settings
from app.service.access import OPEN, KeyFileError, KeyRing, Principal, load_keys

SCOPE_KEY = "bearings.principal"
OPEN_PATHS = frozenset({"/healthz"})
CHALLENGE = (b"www-authenticate", b'Bearer realm="bearings"')


async def get_principal(conn: HTTPConnection) -> Principal:
    """The caller, as the access middleware found it (the open principal without keys).

    ``async`` so that FastAPI calls it on the event loop, not in its thread pool."""
    return conn.scope.get(SCOPE_KEY, OPEN)


PrincipalDep = Annotated[Principal, Depends(get_principal)]


class StartupRefused(RuntimeError):
    """The service must not start as configured; the message says why and what to do."""


def is_loopback(host: str) -> bool:
    """True for an address only this machine can reach (127.0.0.0/8, ::1, localhost)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def startup_keys(settings: Settings) -> KeyRing | None:
    """The configured keys, or None for the open service, which only a loopback host gets.

    Raises :class:`StartupRefused` for an unusable key file, or for no keys on a host
    that others can reach without ``--insecure-open``.
    """
    if settings.api_keys_file is not None:
        try:
            return load_keys(
                settings.api_keys_file,
                default_sessions=settings.key_default_sessions,
                default_particles=settings.max_particles,
                default_frames_per_s=settings.key_default_frames_per_s,
            )
        except KeyFileError as exc:
            raise StartupRefused(f"bad API key file: {exc}") from None
    if not is_loopback(settings.host) and not settings.insecure_open:
        raise StartupRefused(
            f"refusing to listen on {settings.host!r} without API keys: anyone who can reach "
            "it could watch where people are and use every session. Give --api-keys FILE "
            "(BEARINGS_API_KEYS_FILE), listen on 127.0.0.1, or pass --insecure-open "
            "(BEARINGS_INSECURE_OPEN=true) if a trusted network or proxy guards the service"
        )
    return None


def _header(scope: Scope, name: bytes) -> str | None:
    for key, value in scope.get("headers", []):
        if key == name:
            return value.decode("latin-1")
    return None


def same_origin(origin: str, host: str | None) -> bool:
    """True when the browser page's ``origin`` is the server it connects to (``Host``)."""
    if host is None:
        return False
    parts = urlsplit(origin)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        return False
    default = 443 if parts.scheme == "https" else 80
    port = parts.port or default
    server = urlsplit(f"//{host}")
    return (parts.hostname.lower(), port) == (
        (server.hostname or "").lower(),
        server.port or default,
    )


class AccessControl:
    """401 without a valid key (when keys are configured); foreign-origin WebSockets refused."""

    def __init__(self, app: ASGIApp, keys: KeyRing | None, allowed_origins: list[str]) -> None:
        self.app = app
        self.keys = keys
        self.allowed = {o.rstrip("/") for o in allowed_origins}

    def origin_allowed(self, scope: Scope) -> bool:
        origin = _header(scope, b"origin")
        if origin is None:  # not a browser: nothing to check
            return True
        origin = origin.rstrip("/")
        return (
            "*" in self.allowed
            or origin in self.allowed
            or same_origin(origin, _header(scope, b"host"))
        )

    def _key(self, scope: Scope) -> str | None:
        auth = _header(scope, b"authorization")
        if auth is not None:
            scheme, _, token = auth.partition(" ")
            return token.strip() if scheme.lower() == "bearer" and token.strip() else ""
        if scope["type"] == "websocket":
            for name, value in parse_qsl(scope.get("query_string", b"").decode("latin-1")):
                if name == "key":
                    return value
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        if scope["type"] == "websocket" and not self.origin_allowed(scope):
            await _deny(
                scope,
                receive,
                send,
                403,
                "this page's origin may not open WebSockets here; the service allows its own "
                "origin and BEARINGS_ALLOWED_ORIGINS",
            )
            return
        if self.keys is not None and scope["path"] not in OPEN_PATHS:
            key = self._key(scope)
            principal = self.keys.authenticate(key) if key else None
            if principal is None:
                how = "'Authorization: Bearer KEY'" + (
                    " or ?key=KEY" if scope["type"] == "websocket" else ""
                )
                message = (
                    f"this service needs an API key: send {how}"
                    if key is None
                    else "the API key is not valid"
                )
                await _deny(scope, receive, send, 401, message, [CHALLENGE])
                return
            scope[SCOPE_KEY] = principal
        await self.app(scope, receive, send)


async def _deny(
    scope: Scope,
    receive: Receive,
    send: Send,
    status: int,
    message: str,
    headers: list[tuple[bytes, bytes]] | None = None,
) -> None:
    """Answer ``status`` with a JSON message; a WebSocket upgrade is refused before accept."""
    body = json.dumps({"detail": message, "message": message}).encode()
    head = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
        *(headers or []),
    ]
    if scope["type"] == "http":
        await send({"type": "http.response.start", "status": status, "headers": head})
        await send({"type": "http.response.body", "body": body})
        return
    await receive()  # websocket.connect
    if "websocket.http.response" in scope.get("extensions", {}):
        await send({"type": "websocket.http.response.start", "status": status, "headers": head})
        await send({"type": "websocket.http.response.body", "body": body})
    else:  # the server answers 403 to a close before accept
        await send({"type": "websocket.close", "code": 1008, "reason": message[:120]})
