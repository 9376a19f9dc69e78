"""Which sessions' stored state lags what this worker holds, while the store fails.

A session falls behind when a frame it answered could not be journalled (the store
failed, did not answer in time, or no longer held the frames before it). From then on
its frames are answered from memory without writing their entries (a journal with a gap
restores nothing past it), until a checkpoint catches it up. That checkpoint is packed
at some frame F and takes a round trip to land; the entries of frames after F that are
answered meanwhile are held here and written, in order, once it has landed. Only then
does the session journal each frame again. A session behind keeps no entries at all
(only the one catching up does), so a long outage costs no memory.

Used from the event loop only.
"""

from __future__ import annotations

from app.service.store import entry_seq

#: The warning a frame's result carries when the frame is not stored (docs/API.md).
STATE_NOT_PERSISTED = (
    "state_not_persisted: the session store did not take this frame; it was answered "
    "from this worker's memory and will be stored with the session's next checkpoint"
)


class Backlog:
    """Sessions behind (no entries kept) and catching up (entries held after the
    checkpoint in flight)."""

    def __init__(self) -> None:
        self._behind: set[str] = set()
        self._held: dict[str, list[bytes]] = {}

    def __len__(self) -> int:
        return len(self._behind) + len(self._held)

    def lags(self, session_id: str) -> bool:
        """Behind or catching up: the session's stored state does not reach its memory."""
        return session_id in self._behind or session_id in self._held

    def behind(self) -> set[str]:
        """The sessions behind that no checkpoint is catching up yet."""
        return set(self._behind)

    def fall_behind(self, session_id: str) -> None:
        """The session's frames are not being stored (entries held so far are dropped:
        the next checkpoint covers them)."""
        self._held.pop(session_id, None)
        self._behind.add(session_id)

    def hold(self, session_id: str, entry: bytes) -> bool:
        """Keep ``entry`` if a checkpoint of the session is in flight; False if not."""
        held = self._held.get(session_id)
        if held is None:
            return False
        held.append(entry)
        return True

    def catching_up(self, session_id: str) -> None:
        """A checkpoint of the session was just packed: hold its next entries."""
        self._behind.discard(session_id)
        self._held.setdefault(session_id, [])

    def take_held(self, session_id: str, frames: int) -> list[bytes]:
        """The entries held after frame ``frames`` (the landed checkpoint's), in order;
        the session keeps holding what arrives until :meth:`caught_up`."""
        held = self._held.get(session_id)
        if held is None:
            return []
        self._held[session_id] = []
        return [e for e in held if entry_seq(e) > frames]

    def caught_up(self, session_id: str) -> None:
        """Everything the session answered is stored: journal each frame again."""
        self._held.pop(session_id, None)

    def forget(self, session_id: str) -> None:
        """The session is no longer served here."""
        self._behind.discard(session_id)
        self._held.pop(session_id, None)
