"""One session's WebSocket stream: read frames as they come, answer them in order.

Reading and answering run as two tasks, so frames sent faster than the filter runs
reach the session's queue, where they are merged (:mod:`app.service.queueing`),
instead of waiting unread in the socket. At most ``MAX_UNANSWERED`` frames of one
connection are accepted and not yet answered; beyond that the stream stops reading
until answers have gone out (TCP pushes back on the client).

At shutdown (:meth:`StreamRegistry.close_all`) every stream stops reading, sends the
answers of the frames it accepted, and closes with 1012 and a reason that tells the
client to reconnect.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from typing import Any

from fastapi import WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from app.api.convert import frame_input, frame_result_json
from app.api.errors import describe_validation, limit_body
from app.api.schemas import Frame
from app.localization.camera import BoxError
from app.service.access import Principal
from app.service.errors import LimitReached, SessionNotFound
from app.service.sessions import SessionManager
from app.service.types import FrameOutcome

log = logging.getLogger("bearings.streams")

#: Frames of one connection accepted and not yet answered. A waiting frame is merged into
#: its session's queue and costs a future (a few hundred bytes), so this can be generous;
#: it must be, since it caps how many frames a busy session can absorb per step: at 64,
#: a step of 70 ms on a loaded machine let 1,000 frames/s pile up unread in the socket
#: (answers 3 s late); at 1,024 the worst answer stayed under 0.2 s.
MAX_UNANSWERED = 1024
WRITER_GRACE_S = 10.0
RESTART_CODE = 1012
RESTART_REASON = "service restarting: reconnect and resend any frame not answered"
_END = object()


def error_message(code: str, message: str, **extra: object) -> str:
    return json.dumps({"error": {"code": code, "message": message, **extra}})


class Stream:
    """The two tasks of one WebSocket connection to one session."""

    def __init__(
        self, ws: WebSocket, manager: SessionManager, session_id: str, owner: Principal
    ) -> None:
        self.ws = ws
        self.manager = manager
        self.session_id = session_id
        self.owner = owner
        self.limit = ws.app.state.settings.max_message_bytes
        self._answers: asyncio.Queue[Any] = asyncio.Queue()
        self._room = asyncio.Semaphore(MAX_UNANSWERED)
        self._reader: asyncio.Task[None] | None = None
        self._writer: asyncio.Task[None] | None = None
        self._closed = asyncio.Event()
        #: Set when the service is shutting down: the stream waits for :meth:`close`.
        self.stopping = False
        #: Messages taken in that are owed an answer, and answers sent: equal once the
        #: stream has ended normally (a difference is logged: an answer was lost).
        self.received = 0
        self.answered = 0
        self._drained = False  # the writer reached the end of the answers owed

    async def run(self) -> None:
        reader = self._reader = asyncio.create_task(self._read())
        writer = self._writer = asyncio.create_task(self._write())
        writer.add_done_callback(lambda _: reader.cancel())  # the client is gone
        with contextlib.suppress(asyncio.CancelledError):
            await reader
        self._answers.put_nowait(_END)
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await writer
        if self.stopping:
            await self._closed.wait()
        if self._drained and self.received != self.answered:
            log.warning(
                "a stream ended with %d of %d messages unanswered",
                self.received - self.answered,
                self.received,
            )

    def stop_reading(self) -> None:
        """Accept no more frames; the ones accepted are still answered."""
        self.stopping = True
        if self._reader is not None:
            self._reader.cancel()

    async def close(self, code: int, reason: str) -> None:
        """Stop reading, answer every frame accepted, then close with ``code`` and ``reason``."""
        self.stop_reading()
        if self._writer is not None:
            self._answers.put_nowait(_END)
            # The answers normally went out while the service drained; never wait forever.
            _, pending = await asyncio.wait({self._writer}, timeout=WRITER_GRACE_S)
            for task in pending:
                task.cancel()
        try:
            with contextlib.suppress(Exception):
                await self.ws.close(code=code, reason=reason)
        finally:
            self._closed.set()

    def _answer_now(self, text: str) -> None:
        self._owe(text)

    def _owe(self, answer: str | asyncio.Future[FrameOutcome]) -> None:
        """One message taken in: its answer (text, or the future of its result) goes out in turn."""
        self.received += 1
        self.manager.metrics.stream_messages.inc()
        self._answers.put_nowait(answer)

    async def _read(self) -> None:
        while True:
            await self._room.acquire()
            try:
                message = await self.ws.receive()
            except (WebSocketDisconnect, RuntimeError):
                return
            if message["type"] == "websocket.disconnect":
                return
            raw = message.get("text")
            if raw is None and message.get("bytes") is not None:
                raw = message["bytes"].decode("utf-8", errors="replace")
            if raw is None:
                self._room.release()
                continue
            # A text of n characters is at most 4n bytes of UTF-8: only a text that may be
            # over the limit is encoded to count them (a frame is far under it).
            if len(raw) * 4 > self.limit and len(raw.encode("utf-8")) > self.limit:
                self._answer_now(
                    error_message(
                        "message_too_large",
                        f"message is larger than the limit of {self.limit} bytes",
                    )
                )
                continue
            try:
                frame = Frame.model_validate_json(raw)
            except ValidationError as exc:
                code = (
                    "invalid_json" if exc.errors()[0]["type"] == "json_invalid" else "invalid_frame"
                )
                self._answer_now(error_message(code, describe_validation(list(exc.errors()))))
                continue
            try:
                # (with a shared store the session may have to be resumed here first)
                camera = (await self.manager.find(self.session_id, self.owner)).camera
                future = self.manager.submit(
                    self.session_id, frame_input(frame, camera), self.owner
                )
            except BoxError as exc:
                self._answer_now(error_message("invalid_frame", str(exc)))
                continue
            except SessionNotFound as exc:
                self._answer_now(error_message("session_not_found", exc.message))
                self._answers.put_nowait(("close", 1008, "session ended"))
                return
            except LimitReached as exc:
                body = limit_body(exc)
                code, text = str(body.pop("code")), str(body.pop("message"))
                self._answer_now(error_message(code, text, **body))
                continue
            self._owe(future)

    async def _write(self) -> None:
        cache: tuple[FrameOutcome, str] | None = None  # merged frames share one answer
        while True:
            item = await self._answers.get()
            if item is _END:
                self._drained = True
                return
            if isinstance(item, tuple):
                _, code, reason = item
                await self.ws.close(code=code, reason=reason)
                return
            if isinstance(item, str):
                text = item
            else:
                try:
                    outcome = await item
                except SessionNotFound as exc:
                    await self.ws.send_text(error_message("session_not_found", exc.message))
                    await self.ws.close(code=1008, reason="session ended")
                    return
                except LimitReached as exc:
                    body = limit_body(exc)
                    code, message = str(body.pop("code")), str(body.pop("message"))
                    text = error_message(code, message, **body)
                except Exception:  # a bug must not end the stream or lose later answers
                    log.exception("a frame of a stream could not be processed")
                    text = error_message("internal_error", "this frame could not be processed")
                else:
                    if cache is None or cache[0] is not outcome:
                        cache = (outcome, frame_result_json(outcome))
                    text = cache[1]
            await self.ws.send_text(text)
            self.answered += 1
            self.manager.metrics.stream_answers.inc()
            self._room.release()


class StreamRegistry:
    """The open streams, so that a shutdown can close them properly."""

    def __init__(self) -> None:
        self._streams: set[Stream] = set()
        self.stopping = False

    def __len__(self) -> int:
        return len(self._streams)

    async def serve(self, stream: Stream) -> None:
        if self.stopping:
            await stream.ws.close(code=RESTART_CODE, reason=RESTART_REASON)
            return
        self._streams.add(stream)
        try:
            await stream.run()
        finally:
            self._streams.discard(stream)

    def stop_reading(self) -> None:
        """Accept no more frames on any stream (their answers still go out)."""
        self.stopping = True
        for stream in list(self._streams):
            stream.stop_reading()

    async def close_all(self, code: int = RESTART_CODE, reason: str = RESTART_REASON) -> None:
        await asyncio.gather(*(s.close(code, reason) for s in list(self._streams)))
