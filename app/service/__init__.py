"""Sessions: one filter and one narrator per person, with the service's limits."""

from app.service.sessions import (
    LimitReached,
    Session,
    SessionManager,
    SessionNotFound,
    SessionSnapshot,
)

__all__ = ["LimitReached", "Session", "SessionManager", "SessionNotFound", "SessionSnapshot"]
