"""Who may use the service and how much: API keys, the owner of a session, quotas.

A key file has one key a line, either the key alone (the service's default quotas) or
``name key max_sessions max_particles max_frames_per_s`` (``-`` for a default);
``#`` starts a comment, blank lines are skipped. Only SHA-256 digests of the keys are
kept, and a presented key is compared with every digest in constant time
(:func:`hmac.compare_digest`), so neither the keys nor their length leak through
timing. docs/SECURITY.md says how keys are meant to be made, given and rotated.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import re
import threading
from dataclasses import dataclass
from pathlib import Path

from app.service.clock import SYSTEM, Clock

#: Fewer characters than this cannot be a random secret worth the name.
MIN_KEY_CHARS = 16
_NAME = re.compile(r"^[A-Za-z0-9_.@-]{1,64}$")


class KeyFileError(ValueError):
    """The key file cannot be used; the message names the file, the line and the reason."""


@dataclass(frozen=True)
class Principal:
    """Whoever a request speaks for, with its quotas.

    ``name`` None is the open service (no keys configured): it owns nothing and may
    use every session. ``max_particles`` bounds the particles of all the principal's
    live sessions together; ``max_frames_per_s`` is the refill rate of a token bucket
    holding one second of frames.
    """

    name: str | None
    max_sessions: int | None = None
    max_particles: int | None = None
    max_frames_per_s: float | None = None


OPEN = Principal(None)


def _digest(key: str) -> bytes:
    return hashlib.sha256(key.encode("utf-8")).digest()


class KeyRing:
    """The configured keys (as digests) and the principal each stands for."""

    def __init__(self, entries: list[tuple[bytes, Principal]]) -> None:
        self._entries = entries

    def __len__(self) -> int:
        return len(self._entries)

    @property
    def principals(self) -> list[Principal]:
        return [p for _, p in self._entries]

    def authenticate(self, presented: str) -> Principal | None:
        """The principal of ``presented``, or None; every digest is compared, in constant time."""
        digest = _digest(presented)
        found: Principal | None = None
        for stored, principal in self._entries:
            if hmac.compare_digest(stored, digest):
                found = principal
        return found


def _quota(text: str, default: float | None, kind: type, what: str, where: str) -> float | None:
    if text == "-":
        return default
    try:
        value = kind(text)
    except ValueError:
        raise KeyFileError(f"{where}: {what} must be a number or '-', not {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise KeyFileError(f"{where}: {what} must be positive, not {text!r}")
    return value


def parse_keys(
    text: str,
    *,
    source: str = "key file",
    default_sessions: int,
    default_particles: int,
    default_frames_per_s: float,
) -> KeyRing:
    """Parse a key file's text (see the module docstring); raise :class:`KeyFileError`."""
    entries: list[tuple[bytes, Principal]] = []
    names: dict[str, int] = {}
    digests: dict[bytes, int] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        where = f"{source}, line {number}"
        fields = line.split()
        if len(fields) == 1:
            key = fields[0]
            name = "key-" + hashlib.sha256(key.encode()).hexdigest()[:8]
            quotas: tuple[float | None, float | None, float | None] = (
                default_sessions,
                default_particles,
                default_frames_per_s,
            )
        elif len(fields) == 5:
            name, key = fields[0], fields[1]
            if not _NAME.match(name):
                raise KeyFileError(
                    f"{where}: the name {name!r} may only hold letters, digits and _ . @ - "
                    "(at most 64)"
                )
            quotas = (
                _quota(fields[2], default_sessions, int, "max_sessions", where),
                _quota(fields[3], default_particles, int, "max_particles", where),
                _quota(fields[4], default_frames_per_s, float, "max_frames_per_s", where),
            )
        else:
            raise KeyFileError(
                f"{where}: expected 'KEY' or 'NAME KEY MAX_SESSIONS MAX_PARTICLES "
                f"MAX_FRAMES_PER_S', found {len(fields)} fields"
            )
        if len(key) < MIN_KEY_CHARS:
            raise KeyFileError(
                f"{where}: the key has {len(key)} characters; use at least {MIN_KEY_CHARS} "
                "random ones (e.g. python -c 'import secrets; print(secrets.token_urlsafe(32))')"
            )
        if name in names:
            raise KeyFileError(f"{where}: the name {name!r} is already used on line {names[name]}")
        digest = _digest(key)
        if digest in digests:
            raise KeyFileError(f"{where}: the same key is already on line {digests[digest]}")
        names[name] = number
        digests[digest] = number
        sessions, particles, rate = quotas
        entries.append(
            (
                digest,
                Principal(
                    name,
                    max_sessions=None if sessions is None else int(sessions),
                    max_particles=None if particles is None else int(particles),
                    max_frames_per_s=None if rate is None else float(rate),
                ),
            )
        )
    if not entries:
        raise KeyFileError(f"{source}: no keys in the file (only comments or blank lines)")
    return KeyRing(entries)


def load_keys(
    path: Path, *, default_sessions: int, default_particles: int, default_frames_per_s: float
) -> KeyRing:
    """Read and parse a key file; a missing or unreadable file is a :class:`KeyFileError`."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise KeyFileError(f"cannot read the API key file {str(path)!r}: {exc}") from None
    return parse_keys(
        text,
        source=str(path),
        default_sessions=default_sessions,
        default_particles=default_particles,
        default_frames_per_s=default_frames_per_s,
    )


class TokenBucket:
    """``rate`` tokens a second, holding at most ``capacity``; thread-safe; time read
    from ``clock``."""

    def __init__(self, rate: float, capacity: float | None = None, clock: Clock = SYSTEM) -> None:
        self.rate = rate
        self.capacity = max(1.0, rate if capacity is None else capacity)
        self._clock = clock
        self._tokens = self.capacity
        self._at = clock.monotonic()
        self._lock = threading.Lock()

    def take(self, n: float = 1.0) -> float:
        """Take ``n`` tokens and return 0, or take none and return the seconds until there are."""
        with self._lock:
            now = self._clock.monotonic()
            self._tokens = min(self.capacity, self._tokens + (now - self._at) * self.rate)
            self._at = now
            if self._tokens >= n:
                self._tokens -= n
                return 0.0
            return (n - self._tokens) / self.rate
