"""What the session store's side (:mod:`app.service.sharing`) needs of the manager.

:class:`~app.service.sharing.SessionSharing` keeps a worker's sessions in a shared
store: it builds sessions from checkpoints, hands resumed ones over, drops those another
worker took, and counts what it wrote. It does this through :class:`SessionHost`, which
:class:`~app.service.sessions.SessionManager` satisfies, rather than through the
manager itself: the manager creates its sharing, so sharing importing the manager would
close a circle. This module sits below both and imports neither.
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime
from typing import Any, Protocol

from app.service.metrics import Metrics
from app.service.session import Session
from app.service.types import SessionSpec


class SessionHost(Protocol):
    """The sessions one worker serves, as the store's side sees them."""

    @property
    def metrics(self) -> Metrics:
        """Where checkpoints written and sessions resumed are counted."""
        ...

    def build(
        self,
        request: SessionSpec,
        *,
        session_id: str | None = None,
        created_at: datetime | None = None,
        filter_state: Mapping[str, Any] | None = None,
    ) -> Session:
        """A session built from its spec (with a checkpoint's id, creation time and
        filter state when resuming); not yet served."""
        ...

    def sessions(self) -> list[Session]:
        """The sessions served here."""
        ...

    def live(self, session_id: str) -> Session | None:
        """The session if it is served here, else None."""
        ...

    def live_ids(self) -> list[str]:
        """The ids of the sessions served here; safe to call from another thread."""
        ...

    def adopt(self, session: Session) -> None:
        """Serve a session resumed from the store."""
        ...

    def forget(self, session: Session) -> None:
        """Stop serving a session (it lives on in the store)."""
        ...
