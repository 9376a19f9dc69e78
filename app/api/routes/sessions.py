"""Sessions over REST and WebSocket: one filter per session, frames in order."""

from __future__ import annotations

import json

from fastapi import APIRouter, Response, WebSocket, WebSocketDisconnect, status
from pydantic import ValidationError

from app.api.convert import (
    destination_out,
    destination_spec,
    frame_input,
    frame_result,
    session_out,
    session_spec,
)
from app.api.deps import ManagerDep
from app.api.errors import describe_validation, error_responses
from app.api.schemas import (
    DestinationIn,
    DestinationOut,
    Frame,
    FrameResult,
    SessionCreate,
    SessionOut,
)
from app.localization.camera import BoxError
from app.service.sessions import LimitReached, SessionManager, SessionNotFound

router = APIRouter(prefix="/sessions", tags=["sessions"])

#: OpenAPI links: the ``id`` of a new session is the ``session_id`` of the others.
_SESSION_LINKS = {
    name: {
        "operationRef": f"#/paths/~1sessions~1{{session_id}}{suffix}/{method}",
        "parameters": {"session_id": "$response.body#/id"},
    }
    for name, suffix, method in (
        ("GetSession", "", "get"),
        ("PostFrame", "~1frames", "post"),
        ("DeleteSession", "", "delete"),
    )
}


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=SessionOut,
    responses={
        201: {"links": _SESSION_LINKS, "description": "the new session"},
        **error_responses(400, 404, 413, 422, 429),
    },
)
async def create_session(body: SessionCreate, manager: ManagerDep) -> SessionOut:
    """Start localizing one person on a map."""
    return session_out(await manager.create(session_spec(body)))


@router.get("/{session_id}", response_model=SessionOut, responses=error_responses(404))
async def get_session(session_id: str, manager: ManagerDep) -> SessionOut:
    """The session with its latest result (or null)."""
    return session_out(manager.get(session_id))


@router.post(
    "/{session_id}/frames",
    response_model=FrameResult,
    responses=error_responses(400, 404, 413, 422),
)
async def post_frame(session_id: str, frame: Frame, manager: ManagerDep) -> FrameResult:
    """Process one frame; frames of a session are processed strictly in order."""
    camera = manager.get(session_id).camera
    return frame_result(await manager.process(session_id, frame_input(frame, camera)))


@router.put(
    "/{session_id}/destination",
    response_model=DestinationOut,
    responses=error_responses(400, 404, 413, 422),
)
async def put_destination(
    session_id: str, body: DestinationIn, manager: ManagerDep
) -> DestinationOut:
    """Guide the person to an object's label, the nearest object of a class, a region or a
    point; every later ``FrameResult`` carries ``guidance`` and the feedback speaks it."""
    return destination_out(await manager.set_destination(session_id, destination_spec(body)))


@router.delete(
    "/{session_id}/destination",
    status_code=status.HTTP_204_NO_CONTENT,
    responses=error_responses(404),
)
async def delete_destination(session_id: str, manager: ManagerDep) -> Response:
    """Stop guiding; results carry ``guidance: null`` again."""
    manager.clear_destination(session_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.delete(
    "/{session_id}", status_code=status.HTTP_204_NO_CONTENT, responses=error_responses(404)
)
async def delete_session(session_id: str, manager: ManagerDep) -> Response:
    await manager.delete(session_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


async def _send_error(ws: WebSocket, code: str, message: str) -> None:
    await ws.send_text(json.dumps({"error": {"code": code, "message": message}}))


@router.websocket("/{session_id}/stream")
async def stream(ws: WebSocket, session_id: str) -> None:
    """One ``FrameResult`` per ``Frame`` message, in order; bad messages get an error."""
    manager: SessionManager = ws.app.state.manager
    limit = ws.app.state.settings.max_message_bytes
    await ws.accept()
    try:
        manager.get(session_id)
    except SessionNotFound as exc:
        await ws.close(code=status.WS_1008_POLICY_VIOLATION, reason=exc.message[:120])
        return
    try:
        while True:
            message = await ws.receive()
            if message["type"] == "websocket.disconnect":
                return
            raw = message.get("text")
            if raw is None and message.get("bytes") is not None:
                raw = message["bytes"].decode("utf-8", errors="replace")
            if raw is None:
                continue
            if len(raw.encode("utf-8")) > limit:
                await _send_error(
                    ws, "message_too_large", f"message is larger than the limit of {limit} bytes"
                )
                continue
            try:
                frame = Frame.model_validate_json(raw)
            except ValidationError as exc:
                code = (
                    "invalid_json" if exc.errors()[0]["type"] == "json_invalid" else "invalid_frame"
                )
                await _send_error(ws, code, describe_validation(list(exc.errors())))
                continue
            try:
                outcome = await manager.process(
                    session_id, frame_input(frame, manager.get(session_id).camera)
                )
            except BoxError as exc:
                await _send_error(ws, "invalid_frame", str(exc))
                continue
            except SessionNotFound as exc:
                await _send_error(ws, "session_not_found", exc.message)
                await ws.close(code=status.WS_1008_POLICY_VIOLATION, reason="session ended")
                return
            except LimitReached as exc:
                await _send_error(ws, exc.code, str(exc))
                continue
            await ws.send_text(frame_result(outcome).model_dump_json(by_alias=True))
    except WebSocketDisconnect:
        return
