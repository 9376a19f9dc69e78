"""Sessions: one filter and one narrator per person, with the service's limits.

The service speaks its own types (:mod:`app.service.types`, radians); it imports
nothing of HTTP. The API layer converts its wire models to and from them.
"""

from app.service.errors import (
    CapacityReached,
    InvalidSessionSpec,
    LimitReached,
    QuotaReached,
    RequestTooLarge,
    SessionNotFound,
)
from app.service.session import Session, SessionSnapshot
from app.service.sessions import SessionManager
from app.service.types import FrameInput, FrameOutcome, SensorSpec, SessionSpec

__all__ = [
    "CapacityReached",
    "FrameInput",
    "FrameOutcome",
    "InvalidSessionSpec",
    "LimitReached",
    "QuotaReached",
    "RequestTooLarge",
    "SensorSpec",
    "Session",
    "SessionManager",
    "SessionNotFound",
    "SessionSnapshot",
    "SessionSpec",
]
