"""Integrity figures of simulated walks, shared by the experiment suites.

A walk is any record with per-frame arrays ``t`` (s), ``err_m`` (position error),
``converged`` and ``protection_m`` (nan where the filter gave none) and ``step_ms``.
Per set of walks:

* **confidently wrong**: frames with ``converged`` true and the position more than
  ``WRONG_M`` from the truth (the failure a blind user acts on);
* **availability**: share of frames ``converged`` among the frames whose estimate is
  within ``RIGHT_M`` of the truth (how often a right answer is also given with confidence);
* **flips per minute**: ``converged`` turning false while the estimate is within
  ``FLIP_M`` (confidence lost for nothing), per minute of walk;
* **time to first fix**: median over walks of the first converged frame's time (a walk
  that never converges counts as infinite);
* **tail error**: 95th percentile of the position error over converged frames;
* **protection coverage**: share of converged frames whose error is within
  ``protection_m``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

#: Frames converged yet this far off (m) are confidently wrong.
WRONG_M = 1.0
#: Frames within this distance (m) count for availability.
RIGHT_M = 0.5
#: Losing ``converged`` this close (m) to the truth is a flip.
FLIP_M = 0.3


class Walk(Protocol):
    t: np.ndarray
    err_m: np.ndarray
    converged: np.ndarray
    protection_m: np.ndarray
    step_ms: np.ndarray


def flips(walk: Walk) -> int:
    """How often ``converged`` turned false while the estimate was within ``FLIP_M``."""
    c = walk.converged
    lost = np.flatnonzero(c[:-1] & ~c[1:]) + 1
    return int(np.sum(walk.err_m[lost] <= FLIP_M))


def first_fix_s(walk: Walk, since_s: float = 0.0) -> float:
    """Seconds from ``since_s`` to the first converged frame at or after it (inf: never)."""
    hit = np.flatnonzero(walk.converged & (walk.t >= since_s))
    return float(walk.t[hit[0]] - since_s) if hit.size else float("inf")


def first_right_fix_s(walk: Walk, since_s: float = 0.0) -> float:
    """Seconds from ``since_s`` to the first converged frame within ``WRONG_M`` (inf: never)."""
    hit = np.flatnonzero(walk.converged & (walk.t >= since_s) & (walk.err_m <= WRONG_M))
    return float(walk.t[hit[0]] - since_s) if hit.size else float("inf")


def metrics(walks: Sequence[Walk]) -> dict[str, float | int]:
    """The figures over the given walks (pooled over their frames)."""
    err = np.concatenate([w.err_m for w in walks])
    conv = np.concatenate([w.converged for w in walks])
    prot = np.concatenate([w.protection_m for w in walks])
    right = err <= RIGHT_M
    minutes = sum(float(w.t[-1] - w.t[0]) + 0.2 for w in walks) / 60.0
    covered = conv & (err <= np.nan_to_num(prot, nan=-1.0))
    fixes = [first_fix_s(w) for w in walks]
    has_prot = bool(np.isfinite(prot[conv]).any()) if conv.any() else False
    return {
        "seeds": len(walks),
        "frames": int(err.size),
        "converged_frames": int(conv.sum()),
        "wrong_frames": int(np.sum(conv & (err > WRONG_M))),
        "wrong_share": float(np.mean(conv & (err > WRONG_M))),
        "availability": float(conv[right].mean()) if right.any() else float("nan"),
        "flips_per_min": sum(flips(w) for w in walks) / minutes,
        "median_first_fix_s": float(np.median(fixes)),
        "never_fixed": int(np.sum(~np.isfinite(fixes))),
        "tail_err_m": float(np.percentile(err[conv], 95)) if conv.any() else float("nan"),
        "coverage": float(covered.sum() / conv.sum()) if has_prot else float("nan"),
        "median_step_ms": float(np.median(np.concatenate([w.step_ms for w in walks]))),
    }
