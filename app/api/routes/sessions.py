"""Sessions over REST and WebSocket: one filter per session, frames in order.

A session belongs to the API key that created it; for any other key every route here
answers exactly as for a session that does not exist (404).
"""

from __future__ import annotations

from fastapi import APIRouter, Response, WebSocket, status

from app.api.access import PrincipalDep
from app.api.convert import (
    destination_out,
    destination_spec,
    frame_input,
    frame_result,
    session_out,
    session_spec,
)
from app.api.deps import ManagerDep
from app.api.errors import error_responses
from app.api.schemas import (
    DestinationIn,
    DestinationOut,
    Frame,
    FrameResult,
    SessionCreate,
    SessionOut,
)
from app.api.streams import Stream
from app.service.errors import LimitReached, SessionNotFound
from app.service.sessions import SessionManager

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
        **error_responses(400, 404, 413, 422, 429, 503),
    },
)
async def create_session(
    body: SessionCreate, manager: ManagerDep, principal: PrincipalDep
) -> SessionOut:
    """Start localizing one person on a map."""
    return session_out(await manager.create(session_spec(body), principal))


@router.get("/{session_id}", response_model=SessionOut, responses=error_responses(404))
async def get_session(session_id: str, manager: ManagerDep, principal: PrincipalDep) -> SessionOut:
    """The session with its latest result (or null)."""
    return session_out(await manager.settled(session_id, principal))


@router.post(
    "/{session_id}/frames",
    response_model=FrameResult,
    responses=error_responses(400, 404, 413, 422, 429, 503),
)
async def post_frame(
    session_id: str, frame: Frame, manager: ManagerDep, principal: PrincipalDep
) -> FrameResult:
    """Process one frame; frames of a session are processed strictly in order (merged when
    they come faster than the filter runs)."""
    camera = (await manager.find(session_id, principal)).camera
    return frame_result(await manager.process(session_id, frame_input(frame, camera), principal))


@router.put(
    "/{session_id}/destination",
    response_model=DestinationOut,
    responses=error_responses(400, 404, 413, 422),
)
async def put_destination(
    session_id: str, body: DestinationIn, manager: ManagerDep, principal: PrincipalDep
) -> DestinationOut:
    """Guide the person to an object's label, the nearest object of a class, a region or a
    point; every later ``FrameResult`` carries ``guidance`` and the feedback speaks it."""
    plan = await manager.set_destination(session_id, destination_spec(body), principal)
    return destination_out(plan.target, plan.map.layout)


@router.delete(
    "/{session_id}/destination",
    status_code=status.HTTP_204_NO_CONTENT,
    responses=error_responses(404),
)
async def delete_destination(
    session_id: str, manager: ManagerDep, principal: PrincipalDep
) -> Response:
    """Stop guiding; results carry ``guidance: null`` again."""
    await manager.clear_destination(session_id, principal)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.delete(
    "/{session_id}", status_code=status.HTTP_204_NO_CONTENT, responses=error_responses(404)
)
async def delete_session(session_id: str, manager: ManagerDep, principal: PrincipalDep) -> Response:
    await manager.delete(session_id, owner=principal)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


#: Close reason for an unknown session (a close reason holds at most 123 bytes).
NO_SESSION_REASON = (
    "no session with this id for this key (never existed, deleted, expired or restarted)"
)


@router.websocket("/{session_id}/stream")
async def stream(ws: WebSocket, session_id: str, principal: PrincipalDep) -> None:
    """One ``FrameResult`` per ``Frame`` message, in order; bad messages get an error."""
    manager: SessionManager = ws.app.state.manager
    await ws.accept()
    try:
        await manager.find(session_id, principal)  # with a shared store: resumed here
    except SessionNotFound:
        await ws.close(code=status.WS_1008_POLICY_VIOLATION, reason=NO_SESSION_REASON)
        return
    except LimitReached as exc:  # held by another worker for now, or this one is stopping
        await ws.close(code=status.WS_1013_TRY_AGAIN_LATER, reason=str(exc)[:120])
        return
    try:
        await ws.app.state.streams.serve(Stream(ws, manager, session_id, principal))
    finally:
        await manager.let_go(session_id)
