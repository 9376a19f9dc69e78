"""Where sessions live besides a worker's memory: the session store.

``--store memory`` (the default) keeps every session in the one process that serves it,
as a single machine needs: nothing is written anywhere. ``--store redis://HOST:PORT/DB``
shares sessions between workers (docs/API.md, "Session store"): each session's
checkpoint (:mod:`app.service.checkpoint`), a journal of the frames answered since it,
and a lease naming the one worker that may step it, fenced by a token raised at every
new tenure.

One idea a module:

* :mod:`.protocol`: what a store does, and the fencing rule's answers (:class:`Hold`);
* :mod:`.memory`: the embedded store (the same rules on dictionaries);
* :mod:`.scripts`: the Redis keys and the server-side scripts that enforce the rule;
* :mod:`.connection`: the journal's bare hiredis connection;
* :mod:`.group_commit`: journal entries of all sessions, many per round trip;
* :mod:`.writer`: the writes made from the event loop (journal, checkpoints);
* :mod:`.redis_store`: the Redis store;
* :mod:`.health`: whether the store answers, and when to try it again;
* :mod:`.urls`: a store's URL without its password;
* :mod:`.factory`: the store a ``--store`` value names.

Time comes from an injected :class:`~app.service.clock.Clock` (expiry in the memory
store, the health's backoff), so tests move it rather than sleep.
"""

from app.service.store.factory import open_store
from app.service.store.group_commit import JOURNAL_GAP_S, MAX_BATCH
from app.service.store.health import StoreHealth
from app.service.store.memory import MemoryStore
from app.service.store.protocol import Hold, SessionStore, StoreUnavailable, entry_seq
from app.service.store.urls import redacted

__all__ = [
    "JOURNAL_GAP_S",
    "MAX_BATCH",
    "Hold",
    "MemoryStore",
    "SessionStore",
    "StoreHealth",
    "StoreUnavailable",
    "entry_seq",
    "open_store",
    "redacted",
]
