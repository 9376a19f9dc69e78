"""How far errors that do not average out can move a bearing-only fix.

The particle cloud's spread measures the noise the sensor model knows about: independent
bearing errors, which shrink as frames accumulate. A real detector's errors are partly
*systematic*: a box's centre is not the object's (up to a third of its angular half-width
for a wide object seen close), a map drawn a while ago has objects a little off, a camera
is mounted a little turned. Such an error repeats every frame, so many frames do not shrink
it, and a cloud that has seen the same few objects a hundred times is far tighter than
the truth is near. A protection radius taken from the cloud alone is then too small
(measured: a known start standing still behind a 66-degree camera, 40 % of frames beyond
it, docs/results/phone.md).

This module bounds that part from the geometry of what is seen, as satellite navigation
bounds range biases by the dilution of precision: each explained detection gives a row
of the Jacobian of its bearing with respect to a rigid error (dx, dy, dtheta) of the
recent walk (about the current pose), the rows of the last ``window`` frames with
detections are summed into an information matrix and divided by the number of frames (a
bias seen every frame counts once, not once a frame), and with a bearing bias of
``BIAS_DEG`` per object (independent between objects) the position's covariance is
``bias^2`` times the position block of its inverse. The radius holding 99 % of a 2D
Gaussian along its major axis is ``sqrt(chi2_2(0.99)) = 3.03`` of the major axis' std.
With a few objects spread around the person it is a few centimetres; with three objects
in a narrow cone far ahead it is metres, as it should be.

A good fix stays good for a while: walking on, with one object in view at a time, the
person's position is the fix carried by the odometry. So the best geometry bound is kept
as a *fix* (the estimate then, its radius), moved along by the odometry, and the bound
now is the smaller of the geometry's and the carried fix's: the distance from the
estimate to the carried fix, plus its radius then, plus the odometry's drift since (the
motion model's share of the distance walked). A known start is such a fix from the
first frame on (3.03 times its position std), so a person standing still at a known
start keeps its protection however weak the view is.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.config import STEADY_BIAS_DEG, FilterConfig
from app.localization.sensor import Observation
from app.localization.types import Odometry
from app.maps.model import SemanticMap

#: Systematic bearing error per object assumed on top of the noise (degrees).
BIAS_DEG = STEADY_BIAS_DEG
#: Frames with detections whose geometry is pooled.
WINDOW = 20
#: A detection further than this many stds from every visible object of its class is
#: left to clutter and gives no row.
EXPLAINED_STDS = 4.0
#: The estimate moving further than this beyond what the odometry walked between two
#: frames with detections went to another place: the frames before say nothing about
#: the geometry here (m).
JUMP_M = 1.5
#: sqrt of the 99 % quantile of chi-square with 2 degrees of freedom.
Q99_2D = math.sqrt(-2.0 * math.log(0.01))


class BearingGeometry:
    """The recent frames' bearing geometry, the best fix it gave, carried along by the
    odometry, and the radius the truth lies within (module docstring)."""

    def __init__(self, semantic_map: SemanticMap, config: FilterConfig) -> None:
        self.map = semantic_map
        self.config = config
        self.bias_rad = math.hypot(math.radians(BIAS_DEG), config.bearing_std_rad(""))
        #: The odometry's drift: a share of the distance walked (the motion model's).
        self.drift = config.trans_noise_frac
        #: Per frame: (x, y) of the estimate, and its rows (K, 3): dbearing/dx, dbearing/dy
        #: and the detection's score.
        self._frames: deque[tuple[float, float, NDArray[np.float64]]] = deque(maxlen=WINDOW)
        #: Per frame, the weighted sums its rows add to the information matrix
        #: (:func:`_frame_sums`), kept beside ``_frames``.
        self._sums: deque[tuple[float, ...]] = deque(maxlen=WINDOW)
        self.walked_m = 0.0
        #: The fix carried along: a pose (x, y, theta) moved by the odometry since, its
        #: radius then (m) and the distance walked then (m); None without one.
        self._fix: tuple[float, float, float] | None = None
        self._fix_radius_m = math.inf
        self._fix_walked_m = 0.0
        #: Where the last frame was added, and the distance walked then (the jump test).
        self._last_xy = (0.0, 0.0)
        self._last_walked_m = 0.0

    def reset(self) -> None:
        """Forget everything (the belief started over)."""
        self.clear_frames()
        self.walked_m = 0.0
        self._fix = None
        self._fix_radius_m = math.inf
        self._fix_walked_m = 0.0

    def clear_frames(self) -> None:
        """Forget the frames only (the estimate moved to another place)."""
        self._frames.clear()
        self._sums.clear()

    def set_prior(self, pose: tuple[float, float, float], std_xy_m: float) -> None:
        """A known start (x, y, theta) with its position std: a fix to carry along."""
        self._fix = pose
        self._fix_radius_m = Q99_2D * std_xy_m
        self._fix_walked_m = self.walked_m

    def moved(self, odometry: Odometry) -> None:
        """The person moved by ``odometry``: so does the carried fix."""
        self.walked_m += math.hypot(odometry.forward_m, odometry.left_m)
        if self._fix is not None:
            x, y, t = self._fix
            c, s = math.cos(t), math.sin(t)
            self._fix = (
                x + c * odometry.forward_m - s * odometry.left_m,
                y + s * odometry.forward_m + c * odometry.left_m,
                t + odometry.turn_rad,
            )

    def shift_x(self, dx_m: float) -> None:
        """The person rode to another level (:mod:`app.localization.floors`): the carried
        fix and the recent frames move with them by ``dx_m`` in the filter's plane,
        unchanged relative to the level's map."""
        if self._fix is not None:
            x, y, t = self._fix
            self._fix = (x + dx_m, y, t)
        self._frames = deque(((fx + dx_m, fy, rows) for fx, fy, rows in self._frames), WINDOW)
        self._sums = deque((_frame_sums(*f) for f in self._frames), WINDOW)
        self._last_xy = (self._last_xy[0] + dx_m, self._last_xy[1])

    def radius_m(self, x: float, y: float, theta: float) -> float:
        """The 99 % radius around the estimate (x, y, theta) within which the truth lies
        (m): the smaller of the recent geometry's bound and the carried fix's (the
        distance to it, its radius then, and the odometry's drift since: either holds on
        its own). A geometry bound better than the carried one becomes the new fix.
        inf while nothing fixes a position."""
        geometry = self._geometry_radius_m(x, y)
        carried = math.inf
        if self._fix is not None:
            fx, fy, _ = self._fix
            carried = (
                math.hypot(x - fx, y - fy)
                + self._fix_radius_m
                + self.drift * (self.walked_m - self._fix_walked_m)
            )
        if geometry < carried:
            self._fix, self._fix_radius_m, self._fix_walked_m = (
                (x, y, theta),
                geometry,
                self.walked_m,
            )
            return geometry
        return carried

    def add(
        self,
        x: float,
        y: float,
        theta: float,
        obs: Observation,
        visible: NDArray[np.bool_] | None,
    ) -> None:
        """Add one frame's explained detections, seen from the estimate (x, y, theta)."""
        if obs.empty:
            return
        if self._frames and math.hypot(x - self._last_xy[0], y - self._last_xy[1]) > (
            self.walked_m - self._last_walked_m + JUMP_M
        ):
            self.clear_frames()  # the estimate went to another place: not seen here
        self._last_xy, self._last_walked_m = (x, y), self.walked_m
        rows = np.empty((obs.det_bearing.size, 3))
        use_visible = visible is not None
        n = _explained_rows(
            x, y, theta, obs.det_bearing, obs.det_group, obs.det_score, obs.group_kappa,
            obs.member_start, obs.members, self.map.object_xy.reshape(-1, 2),
            visible if use_visible else _NO_ROW, use_visible, EXPLAINED_STDS, rows,
        )  # fmt: skip
        if n:
            self._append((x, y, rows[:n]))

    def _append(self, frame: tuple[float, float, NDArray[np.float64]]) -> None:
        self._frames.append(frame)
        self._sums.append(_frame_sums(*frame))

    def _geometry_radius_m(self, x: float, y: float) -> float:
        """The bound of the bearings' geometry alone (module docstring)."""
        if not self._frames:
            return math.inf
        frames = len(self._sums)
        aa, ab, bb, ac0, bc0, c0c0 = (
            sum(column) / frames for column in zip(*self._sums, strict=True)
        )
        # A rotation dtheta about (x, y) moves a frame's pose (fx, fy) by
        # (-(fy - y), fx - x) dtheta and turns it by dtheta: a row's third entry is
        # c0 + a y - b x, with c0 = -1 - a fy + b fx (what _frame_sums summed).
        ac = ac0 + y * aa - x * ab
        bc = bc0 + y * ab - x * bb
        cc = c0c0 + y * y * aa + x * x * bb + 2.0 * (y * ac0 - x * bc0 - x * y * ab)
        # The position block of the inverse: the Schur complement of the heading, and
        # its smaller eigenvalue (a symmetric 2 x 2, in closed form).
        if cc <= 0.0:
            return math.inf
        p, q, r = aa - ac * ac / cc, ab - ac * bc / cc, bb - bc * bc / cc
        low = 0.5 * (p + r) - math.hypot(0.5 * (p - r), q)
        if not low > 1e-12:
            return math.inf
        return Q99_2D * self.bias_rad / math.sqrt(low)

    def checkpoint(self) -> dict[str, Any]:
        return {
            "frames": list(self._frames),
            "walked": self.walked_m,
            "fix": self._fix,
            "fix_radius": self._fix_radius_m,
            "fix_walked": self._fix_walked_m,
            "last": (*self._last_xy, self._last_walked_m),
        }

    def restore(self, state: Any) -> None:
        """From :meth:`checkpoint` (None: a checkpoint from before it existed)."""
        self.reset()
        if state is None:
            return
        self.walked_m = float(state["walked"])
        lx, ly, lw = state["last"]
        self._last_xy, self._last_walked_m = (float(lx), float(ly)), float(lw)
        fix = state["fix"]
        self._fix = None if fix is None else (float(fix[0]), float(fix[1]), float(fix[2]))
        self._fix_radius_m = float(state["fix_radius"])
        self._fix_walked_m = float(state["fix_walked"])
        for fx, fy, rows in state["frames"]:
            self._append((float(fx), float(fy), np.asarray(rows, dtype=np.float64).reshape(-1, 3)))


#: The visibility row passed when there is none (not read).
_NO_ROW = np.zeros(1, dtype=np.bool_)


@njit(cache=True, nogil=True)
def _explained_rows(x, y, theta, det_bearing, det_group, det_score, group_kappa, member_start, members, obj_xy, visible, use_visible, explained_stds, out):  # fmt: skip  # noqa: E501  # pragma: no cover - compiled
    """Each detection's Jacobian row at the pose (x, y, theta) for the visible object of
    its class it points at most nearly, if within ``explained_stds`` of its class's
    std: ``out[i] = (dbearing/dx, dbearing/dy, score)``; returns how many rows."""
    n = 0
    two_pi = 2.0 * np.pi
    for k in range(det_bearing.shape[0]):
        g = det_group[k]
        best = np.inf
        bx = 0.0
        by = 0.0
        for j in range(member_start[g], member_start[g + 1]):
            o = members[j]
            if use_visible and not visible[o]:
                continue
            dx = obj_xy[o, 0] - x
            dy = obj_xy[o, 1] - y
            off = np.arctan2(dy, dx) - theta - det_bearing[k]
            off = abs(off - two_pi * np.round(off / two_pi))
            if off < best:
                best = off
                bx = dx
                by = dy
        if best > explained_stds / np.sqrt(max(group_kappa[g], 1e-12)):
            continue
        d2 = bx * bx + by * by
        if d2 < 1e-6:
            continue
        out[n, 0] = by / d2
        out[n, 1] = -bx / d2
        out[n, 2] = det_score[k]
        n += 1
    return n


def _frame_sums(
    fx: float, fy: float, rows: NDArray[np.float64]
) -> tuple[float, float, float, float, float, float]:
    """One frame's weighted sums of its rows (a, b; weight w; c0 = -1 - a fy + b fx):
    w a a, w a b, w b b, w a c0, w b c0, w c0 c0."""
    a, b, w = rows[:, 0], rows[:, 1], rows[:, 2]
    c0 = -1.0 - a * fy + b * fx
    wa, wb = w * a, w * b
    add = np.add.reduce
    return (
        float(add(wa * a)),
        float(add(wa * b)),
        float(add(wb * b)),
        float(add(wa * c0)),
        float(add(wb * c0)),
        float(add(w * c0 * c0)),
    )
