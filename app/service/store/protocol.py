"""What a session store does (:class:`SessionStore`) and what its answers mean.

Every write names the writer twice: its owner token (which process) and the fencing
token it was given when it took the session's lease (which tenure). A write is refused
when the session was taken since by anyone, even by a process that has let it go again,
so a worker that stalled or lost its connection and comes back can never overwrite a
newer state. A lease that vanished without anyone taking the session (it ran out while
the store was unreachable, or the store restarted empty) is taken back by the writer
that still holds the session, rather than lost.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import IntEnum
from typing import Protocol


class StoreUnavailable(RuntimeError):
    """The session store cannot be reached or refused an operation."""


class Hold(IntEnum):
    """What a renewal, a checkpoint or a journal entry found of the writer's lease."""

    #: Another worker took the session since (or it was deleted): stop serving it.
    LOST = 0
    #: Still held; the write was made.
    HELD = 1
    #: The lease had vanished and nobody took the session since: taken back (the
    #: store may have lost the session's state with it: a checkpoint should follow).
    RETAKEN = 2
    #: A journal entry held (or taken back) but not written: the stored frames do not
    #: end right before it (the store lost them, or never got them), so a checkpoint
    #: must come first.
    GAP = 3


class SessionStore(Protocol):
    """Checkpoints, journals and leases of sessions (see the package docstring).

    ``shared`` is False for a store only this process sees: the manager then keeps
    sessions in memory only and writes nothing. ``lease_s`` is the life of a lease,
    ``ttl_s`` that of a session's stored state (the idle timeout).
    """

    shared: bool

    def ping(self) -> None:
        """Raise unless the store answers."""
        ...

    def acquire(self, session_id: str, owner: str, lease_s: float, ttl_s: float) -> int | None:
        """Take (or keep) the session's lease and return its fencing token; None while
        another owner holds it. Taking a lease not already held issues a new token."""
        ...

    def renew(
        self, items: Sequence[tuple[str, int]], owner: str, lease_s: float, ttl_s: float
    ) -> list[Hold]:
        """Extend the leases (session id, fencing token) ``owner`` holds; take back those
        that vanished; LOST for each one another owner took."""
        ...

    def release(self, session_ids: Sequence[str], owner: str) -> None:
        """Give up the leases ``owner`` holds (others' leases are left alone)."""
        ...

    def load(self, session_id: str) -> tuple[bytes | None, list[bytes]]:
        """The checkpoint (None if there is none) and the journal entries after it."""
        ...

    async def save(
        self,
        items: Sequence[tuple[str, bytes, int, int]],
        owner: str,
        lease_s: float,
        ttl_s: float,
    ) -> list[bool]:
        """Write checkpoints (session id, bytes, frames covered, fencing token) where
        ``owner`` holds the lease or takes it back, and drop the journal entries they
        cover; False where the session was lost. On the event loop, like :meth:`append`."""
        ...

    async def append(
        self, session_id: str, entry: bytes, owner: str, fence: int, lease_s: float, ttl_s: float
    ) -> Hold:
        """Add a journal entry (on the event loop) if the stored frames end right
        before it: HELD once it is stored (the lease maybe taken back) or if the stored
        frames cover it already, GAP when it would leave a gap and was not written,
        LOST when another owner has the session."""
        ...

    def delete(self, session_id: str, ttl_s: float) -> None:
        """Forget the session (checkpoint, journal, lease), and for ``ttl_s`` refuse to
        let a lease on it be taken back."""
        ...

    async def aclose(self) -> None:
        """Close what belongs to the event loop (the connection it writes through), from it."""
        ...

    def close(self) -> None:
        """Close the blocking connections (after :meth:`aclose`)."""
        ...


def entry_seq(entry: bytes) -> int:
    """The step number a journal entry starts with (``SEQ|...``)."""
    return int(entry.partition(b"|")[0])
