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

from app.localization.config import NARROW_CAMERA_FOV_DEG, STEADY_BIAS_DEG, FilterConfig
from app.localization.fastmath import PAIRWISE_BLOCK, pairwise_sum
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
#: The search along the weak direction stops at this many times the linearized bound,
#: and at this many metres (a larger bound gains nothing: the gate holds at 5 m).
RIDGE_CAP = 8.0
RIDGE_MAX_M = 10.0
#: Halvings of the step that left the bias (a 2^-5 share of it).
RIDGE_BISECTIONS = 5
#: Cameras this wide or wider see objects on every side, which pin the position along
#: any one line of sight: the ridge is searched for narrower ones only (degrees).
RIDGE_FOV_DEG = NARROW_CAMERA_FOV_DEG
#: Lines (each searched both ways) the ridge is looked for along, evenly spaced.
RIDGE_DIRECTIONS = 4
#: sqrt of the 99 % quantile of chi-square with 2 degrees of freedom.
Q99_2D = math.sqrt(-2.0 * math.log(0.01))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _excess(
    fx, fy, ox, oy, w, base, x, y, step, ux, uy, limit, frames
):  # fmt: skip  # pragma: no cover - compiled
    """:meth:`BearingGeometry._ridge_reference`'s ``excess``: the recent walk moved by
    ``step`` along (ux, uy), its heading re-solved (three Gauss-Newton steps), less the
    bias's limit: the frames' mean weighted squared bearing change minus ``limit``."""
    n = fx.shape[0]
    two_pi = 2.0 * np.pi
    turn = 0.0
    for _ in range(3):
        c, s = math.cos(turn), math.sin(turn)
        hess = 0.0
        grad = 0.0
        for i in range(n):
            rx, ry = fx[i] - x, fy[i] - y
            qx, qy = c * rx - s * ry, s * rx + c * ry
            dx, dy = ox[i] - x - qx - step * ux, oy[i] - y - qy - step * uy
            d2 = max(dx * dx + dy * dy, 1e-6)
            res = math.atan2(dy, dx) - turn - base[i]
            res = res - two_pi * np.round(res / two_pi)
            jac = -(dx * qx + dy * qy) / d2 - 1.0
            hess += w[i] * jac * jac
            grad += w[i] * jac * res
        if not hess > 0.0:
            break
        turn -= grad / hess
    c, s = math.cos(turn), math.sin(turn)
    total = 0.0
    for i in range(n):
        rx, ry = fx[i] - x, fy[i] - y
        px = x + c * rx - s * ry + step * ux
        py = y + s * rx + c * ry + step * uy
        res = math.atan2(oy[i] - py, ox[i] - px) - turn - base[i]
        res = res - two_pi * np.round(res / two_pi)
        total += w[i] * res * res
    return total / frames - limit


@njit(cache=True, nogil=True, error_model="numpy")
def _ridge(
    fx, fy, ox, oy, w, x, y, ux, uy, linear, limit, frames, cap, bisections
):  # fmt: skip  # pragma: no cover - compiled
    """:meth:`BearingGeometry._ridge_reference`, compiled (the same steps, in loops)."""
    n = fx.shape[0]
    base = np.empty(n)
    for i in range(n):
        base[i] = math.atan2(oy[i] - fy[i], ox[i] - fx[i])
    best = 0.0
    for sign in (1.0, -1.0):
        lo, hi = 0.0, linear
        while (
            _excess(fx, fy, ox, oy, w, base, x, y, sign * hi, ux, uy, limit, frames) <= 0.0
            and hi < cap
        ):
            lo, hi = hi, min(2.0 * hi, cap)
        if (
            hi >= cap
            and _excess(fx, fy, ox, oy, w, base, x, y, sign * hi, ux, uy, limit, frames) <= 0.0
        ):
            return cap
        for _ in range(bisections):
            mid = 0.5 * (lo + hi)
            if _excess(fx, fy, ox, oy, w, base, x, y, sign * mid, ux, uy, limit, frames) <= 0.0:
                lo = mid
            else:
                hi = mid
        best = max(best, lo)
    return best


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
        #: Their means over the frames (:meth:`_means`), kept until ``_sums`` changes.
        self._sum_means: tuple[float, float, float, float, float, float] | None = None
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
        self._sum_means = None

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
        self._sum_means = None
        self._last_xy = (self._last_xy[0] + dx_m, self._last_xy[1])

    def radius_m(self, x: float, y: float, theta: float) -> float:
        """The 99 % radius around the estimate (x, y, theta) within which the truth lies
        (m): the smaller of the recent geometry's bound and the carried fix's (the
        distance to it, its radius then, and the odometry's drift since: either holds on
        its own). A geometry bound better than the carried one becomes the new fix.
        inf while nothing fixes a position."""
        geometry = self._geometry_radius_m(x, y)
        carried = self._carried_m(x, y)
        if geometry < carried:
            self._fix, self._fix_radius_m, self._fix_walked_m = (
                (x, y, theta),
                geometry,
                self.walked_m,
            )
            return geometry
        return carried

    def bound_m(self, x: float, y: float) -> float:
        """:meth:`radius_m`'s value at (x, y) without keeping anything: for a pose that
        is only asked about (a candidate), not the frame's estimate."""
        return min(self._geometry_radius_m(x, y), self._carried_m(x, y))

    def _carried_m(self, x: float, y: float) -> float:
        """The carried fix's bound at (x, y): the distance to it, its radius then, and
        the odometry's drift since (inf without a fix)."""
        if self._fix is None:
            return math.inf
        fx, fy, _ = self._fix
        walked = self.walked_m - self._fix_walked_m
        return math.hypot(x - fx, y - fy) + self._fix_radius_m + self.drift * walked

    def offer_fix(self, pose: tuple[float, float, float], radius_m: float) -> None:
        """A fix known otherwise (the stop of the connector a ride ended in): carried
        from now on, unless the carried one already bounds the person tighter there."""
        if self._carried_m(pose[0], pose[1]) > radius_m:
            self._fix, self._fix_radius_m, self._fix_walked_m = pose, radius_m, self.walked_m

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
        self._sum_means = None

    def _means(self) -> tuple[float, float, float, float, float, float]:
        """The frames' sums (:func:`_frame_sums`) averaged over the frames, kept until a
        frame comes or goes (a narrow camera's radius and reach read them twice a frame)."""
        means = self._sum_means
        if means is None:
            frames = len(self._sums)
            columns = zip(*self._sums, strict=True)
            aa, ab, bb, ac0, bc0, c0c0 = (total / frames for total in map(sum, columns))
            means = self._sum_means = (aa, ab, bb, ac0, bc0, c0c0)
        return means

    def _position_information(self, x: float, y: float) -> tuple[float, float, float] | None:
        """The position block of the recent geometry's information about (x, y), the
        heading solved out (the Schur complement: p, q, r of a symmetric 2 x 2), or None
        when the heading is not pinned at all."""
        aa, ab, bb, ac0, bc0, c0c0 = self._means()
        # A rotation dtheta about (x, y) moves a frame's pose (fx, fy) by
        # (-(fy - y), fx - x) dtheta and turns it by dtheta: a row's third entry is
        # c0 + a y - b x, with c0 = -1 - a fy + b fx (what _frame_sums summed).
        ac = ac0 + y * aa - x * ab
        bc = bc0 + y * ab - x * bb
        cc = c0c0 + y * y * aa + x * x * bb + 2.0 * (y * ac0 - x * bc0 - x * y * ab)
        if cc <= 0.0:
            return None
        return aa - ac * ac / cc, ab - ac * bc / cc, bb - bc * bc / cc

    def _geometry_radius_m(self, x: float, y: float) -> float:
        """The bound of the bearings' geometry alone (module docstring)."""
        if not self._frames:
            return math.inf
        block = self._position_information(x, y)
        if block is None:
            return math.inf
        p, q, r = block
        # The position block of the inverse's major axis: the smaller eigenvalue of the
        # information's (a symmetric 2 x 2, in closed form).
        low = 0.5 * (p + r) - math.hypot(0.5 * (p - r), q)
        if not low > 1e-12:
            return math.inf
        return Q99_2D * self.bias_rad / math.sqrt(low)

    def reach_m(self, x: float, y: float, bound: float) -> float:
        """The protection's bound: ``bound`` (:meth:`radius_m`'s, this frame) with the
        recent geometry's searched without linearizing (:meth:`_reach_m`). The gate keeps
        the linearized one: the ridge on the gate cost availability (office_suite
        vio-pinhole66 0.61 -> 0.48) and removed no wrong fix."""
        if self.config.fov_deg >= RIDGE_FOV_DEG:
            return bound  # objects on every side: no long ridge for the line to miss
        linear = self._geometry_radius_m(x, y)
        if not math.isfinite(linear) or bound < linear:  # the carried fix is tighter
            return bound
        return max(bound, self._reach_m(x, y, linear))

    def _reach_m(self, x: float, y: float, linear: float) -> float:
        """How far the recent walk moved rigidly keeps its bearings within the bias,
        searched along rays from the weak direction round (the ridge along the sight
        need not be the weakest one)."""
        block = self._position_information(x, y)
        if linear > RIDGE_MAX_M or block is None:
            return linear
        p, q, r = block
        low = 0.5 * (p + r) - math.hypot(0.5 * (p - r), q)
        # Rays from the weak direction (the eigenvector of ``low``) round, searched
        # without linearizing: the ridge along the sight need not be the weakest one.
        ux, uy = (q, low - p) if abs(p - low) > abs(r - low) else (low - r, q)
        start = math.atan2(uy, ux) if math.hypot(ux, uy) > 0.0 else 0.0
        reach = linear
        points = self._points()
        for k in range(RIDGE_DIRECTIONS):
            angle = start + math.pi * k / RIDGE_DIRECTIONS
            ux, uy = math.cos(angle), math.sin(angle)
            reach = max(reach, self._ridge_m(points, x, y, ux, uy, linear))
        return reach

    def _ridge_m(
        self,
        points: tuple[NDArray[np.float64], ...],
        x: float,
        y: float,
        ux: float,
        uy: float,
        linear: float,
    ) -> float:
        """:meth:`_ridge_reference` (on :meth:`_points`), compiled (:func:`_ridge`). The
        arrays are made contiguous (a row's weight is a strided column) so that the
        kernel compiled at start-up is the one every step calls."""
        fx, fy, ox, oy, w = (np.ascontiguousarray(v, dtype=np.float64) for v in points)
        return float(
            _ridge(
                fx, fy, ox, oy, w, float(x), float(y), float(ux), float(uy), float(linear),
                (Q99_2D * self.bias_rad) ** 2, float(len(self._frames)),
                min(RIDGE_CAP * linear, RIDGE_MAX_M), RIDGE_BISECTIONS,
            )
        )  # fmt: skip

    def _ridge_reference(self, x: float, y: float, ux: float, uy: float, linear: float) -> float:
        """How far along +-(ux, uy) the recent walk, moved rigidly (the heading re-solved
        for each step), keeps its bearings within the bias: the mean over frames of the
        weighted squared bearing change at most ``(Q99_2D * bias)^2`` (what the
        linearization bounds at ``linear``). Moving back from objects in a narrow cone
        ahead changes their bearings far less than moving towards them (measured: a
        66-degree camera, paper_office seed 3, 1.3-1.6 m back along the sight where
        the linearization said 0.43-0.50 m)."""
        fx, fy, ox, oy, w = self._points()
        frames = len(self._frames)
        limit = (Q99_2D * self.bias_rad) ** 2
        base = np.arctan2(oy - fy, ox - fx)
        rx, ry = fx - x, fy - y
        cap = min(RIDGE_CAP * linear, RIDGE_MAX_M)

        def excess(step: float) -> float:
            # The heading change minimizing the bearings' change (Gauss-Newton).
            turn = 0.0
            for _ in range(3):
                c, s = math.cos(turn), math.sin(turn)
                qx, qy = c * rx - s * ry, s * rx + c * ry  # the frame swung about (x, y)
                dx, dy = ox - x - qx - step * ux, oy - y - qy - step * uy
                d2 = np.maximum(dx * dx + dy * dy, 1e-6)
                res = np.arctan2(dy, dx) - turn - base
                res = res - 2.0 * np.pi * np.round(res / (2.0 * np.pi))
                # d res / d turn: the frame's position swinging, less the turn itself.
                jac = -(dx * qx + dy * qy) / d2 - 1.0
                hess = float(np.dot(w, jac * jac))
                if not hess > 0.0:
                    break
                turn -= float(np.dot(w, jac * res)) / hess
            c, s = math.cos(turn), math.sin(turn)
            px = x + c * rx - s * ry + step * ux
            py = y + s * rx + c * ry + step * uy
            res = np.arctan2(oy - py, ox - px) - turn - base
            res = res - 2.0 * np.pi * np.round(res / (2.0 * np.pi))
            return float(np.dot(w, res * res)) / frames - limit

        best = 0.0
        for sign in (1.0, -1.0):
            lo, hi = 0.0, linear
            while excess(sign * hi) <= 0.0 and hi < cap:  # outward until it leaves
                lo, hi = hi, min(2.0 * hi, cap)
            if hi >= cap and excess(sign * hi) <= 0.0:
                return cap
            for _ in range(RIDGE_BISECTIONS):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if excess(sign * mid) <= 0.0 else (lo, mid)
            best = max(best, lo)
        return best

    def _points(
        self,
    ) -> tuple[
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
    ]:
        """The recent frames' rows as points: each row's frame position, its object's
        position (the row's (a, b) is (oy - fy, -(ox - fx)) / d^2) and its weight."""
        rows = np.concatenate([r for _, _, r in self._frames])
        fx = np.concatenate([np.full(len(r), f) for f, _, r in self._frames])
        fy = np.concatenate([np.full(len(r), f) for _, f, r in self._frames])
        a, b, w = rows[:, 0], rows[:, 1], rows[:, 2]
        inv = 1.0 / np.maximum(a * a + b * b, 1e-12)
        return fx, fy, fx - b * inv, fy + a * inv, w

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
    w a a, w a b, w b b, w a c0, w b c0, w c0 c0.

    Compiled (:func:`_frame_sums_compiled`): the numpy form's dozen calls on a frame's
    ten-odd rows cost about 10 us a frame, the compiled one a third of a microsecond.
    Beyond ``PAIRWISE_BLOCK`` rows, numpy's (:func:`_frame_sums_reference`)."""
    if rows.shape[0] > PAIRWISE_BLOCK:
        return _frame_sums_reference(fx, fy, rows)
    return _frame_sums_compiled(float(fx), float(fy), rows)


def _frame_sums_reference(
    fx: float, fy: float, rows: NDArray[np.float64]
) -> tuple[float, float, float, float, float, float]:
    """:func:`_frame_sums` in numpy (the compiled form is held to it to the last bit)."""
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


def warm_up() -> None:
    """Compile :func:`_frame_sums_compiled` now (or load it from the disk cache), for
    rows as a step makes them and as a restored checkpoint may hold them (read-only)."""
    rows = np.zeros((1, 3))
    _frame_sums(0.0, 0.0, rows)
    rows.flags.writeable = False
    _frame_sums(0.0, 0.0, rows)


@njit(cache=True, nogil=True)
def _frame_sums_compiled(fx, fy, rows):  # fmt: skip  # pragma: no cover - compiled
    """:func:`_frame_sums_reference` for at most ``PAIRWISE_BLOCK`` rows: numpy's
    element-wise arithmetic in its order (no fused multiply-add without fastmath), each
    column summed as numpy's ``add.reduce`` sums it."""
    n = rows.shape[0]
    p = np.empty((6, max(n, 1)))
    for i in range(n):
        a = rows[i, 0]
        b = rows[i, 1]
        w = rows[i, 2]
        c0 = (-1.0 - a * fy) + b * fx
        wa = w * a
        wb = w * b
        p[0, i] = wa * a
        p[1, i] = wa * b
        p[2, i] = wb * b
        p[3, i] = wa * c0
        p[4, i] = wb * c0
        p[5, i] = (w * c0) * c0
    return (
        pairwise_sum(p[0], n), pairwise_sum(p[1], n), pairwise_sum(p[2], n),
        pairwise_sum(p[3], n), pairwise_sum(p[4], n), pairwise_sum(p[5], n),
    )  # fmt: skip
