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
from app.api.schemas import (
    DestinationIn,
    DestinationOut,
    ErrorBody,
    Frame,
    FrameResult,
    SessionCreate,
    SessionOut,
)
from app.api.streams import Stream
from app.service.sessions import SessionManager, SessionNotFound

router = APIRouter(prefix="/sessions", tags=["sessions"])


@router.post("", status_code=status.HTTP_201_CREATED, response_model=SessionOut)
async def create_session(
    body: SessionCreate, manager: ManagerDep, principal: PrincipalDep
) -> SessionOut:
    """Start localizing one person on a map."""
    return session_out(await manager.create(session_spec(body), principal))


@router.get("/{session_id}", response_model=SessionOut)
async def get_session(session_id: str, manager: ManagerDep, principal: PrincipalDep) -> SessionOut:
    """The session with its latest result (or null)."""
    return session_out(manager.get(session_id, principal))


@router.post("/{session_id}/frames", response_model=FrameResult)
async def post_frame(
    session_id: str, frame: Frame, manager: ManagerDep, principal: PrincipalDep
) -> FrameResult:
    """Process one frame; frames of a session are processed strictly in order (merged when
    they come faster than the filter runs)."""
    camera = manager.get(session_id, principal).camera
    return frame_result(await manager.process(session_id, frame_input(frame, camera), principal))


@router.put(
    "/{session_id}/destination",
    response_model=DestinationOut,
    responses={422: {"model": ErrorBody, "description": "unknown or unreachable destination"}},
)
async def put_destination(
    session_id: str, body: DestinationIn, manager: ManagerDep, principal: PrincipalDep
) -> DestinationOut:
    """Guide the person to an object's label, the nearest object of a class, a region or a
    point; every later ``FrameResult`` carries ``guidance`` and the feedback speaks it."""
    target = await manager.set_destination(session_id, destination_spec(body), principal)
    return destination_out(target)


@router.delete("/{session_id}/destination", status_code=status.HTTP_204_NO_CONTENT)
async def delete_destination(
    session_id: str, manager: ManagerDep, principal: PrincipalDep
) -> Response:
    """Stop guiding; results carry ``guidance: null`` again."""
    manager.clear_destination(session_id, principal)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.delete("/{session_id}", status_code=status.HTTP_204_NO_CONTENT)
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
        manager.get(session_id, principal)
    except SessionNotFound:
        await ws.close(code=status.WS_1008_POLICY_VIOLATION, reason=NO_SESSION_REASON)
        return
    await ws.app.state.streams.serve(Stream(ws, manager, session_id, principal))
