"""Keep session ids and API keys out of every log line.

Paths are logged by uvicorn (access log, WebSocket accept lines) and could be logged by
anything that handles a request; a session id is a bearer secret for its session, so
the part after ``/sessions/`` and any ``key=`` query value are replaced before a record
is written. The filter sits on uvicorn's loggers (see :func:`install_redaction`) and on
the handlers of the server's log configuration (app/server.py).
"""

from __future__ import annotations

import logging
import re

_SESSION = re.compile(r"(/sessions/)[^/\s?#\"'<>]+")
_KEY = re.compile(r"([?&;]key=)[^&\s\"'#]*", re.IGNORECASE)
_BEARER = re.compile(r"(bearer\s+)[^\s\"',]+", re.IGNORECASE)

#: Loggers whose records may carry request paths.
LOGGERS = ("uvicorn", "uvicorn.access", "uvicorn.error", "websockets", "websockets.server")


def redact(text: str) -> str:
    """``text`` with session ids, ``key=`` values and bearer tokens replaced."""
    text = _SESSION.sub(r"\1{id}", text)
    text = _KEY.sub(r"\1***", text)
    return _BEARER.sub(r"\1***", text)


class RedactFilter(logging.Filter):
    """Redacts a record's message and arguments in place (keeps the arguments' shape,
    which uvicorn's access formatter relies on)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.msg, str):
            record.msg = redact(record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(redact(a) if isinstance(a, str) else a for a in record.args)
        elif isinstance(record.args, dict):
            record.args = {
                k: redact(v) if isinstance(v, str) else v for k, v in record.args.items()
            }
        if record.exc_info and not record.exc_text:
            record.exc_text = redact(logging.Formatter().formatException(record.exc_info))
        elif record.exc_text:
            record.exc_text = redact(record.exc_text)
        return True


_FILTER = RedactFilter()


def install_redaction() -> None:
    """Put the filter on the loggers that see request paths (idempotent)."""
    for name in LOGGERS:
        logger = logging.getLogger(name)
        if _FILTER not in logger.filters:
            logger.addFilter(_FILTER)
