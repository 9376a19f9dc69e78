"""The sensor model: how well a set of bearing-only semantic detections fits a pose.

This is the paper's model (Section III-B), written once here:

* Eq. (2): detections are grouped by class, O_i = {z_k : c_k = c_i}, classes are
  independent, and the likelihood is the product over classes. Each detection's
  likelihood enters with the exponent 1/size(O_i), so a class seen many times (six
  windows) does not drown a class seen once (the door).
* Eq. (3): a detection's likelihood is the best over the map objects of its class,
  max_n P(z_k | s, M^n) with c(M^n) = c_k: maximum-likelihood correspondence, no data
  association and no object identities.
* The bearing error follows a **von Mises** distribution with concentration
  kappa = 1 / sigma_c^2 per class (sigma_c from :class:`FilterConfig`). Its density
  depends on the error only through cos(error), so the model compares unit vectors
  (a dot product) instead of calling atan2.
* The detection score w in [0, 1] tempers the likelihood, P^w: w = 0 carries no
  information, w = 1 the full likelihood.

Bearings' additions, each switchable in :class:`FilterConfig`:

* ``visibility``: only objects inside the field of view, within range and in line of
  sight of the particle can explain a detection (line of sight from the per-map
  :mod:`visibility grid <app.maps.visibility>`).
* ``clutter``: each detection's likelihood is a mixture (1 - eps) vonMises + eps
  uniform, eps = ``clutter_prob``; a detection that nothing explains (a false
  positive) then costs a bounded amount instead of killing the right particle.
* ``object_spread_m``: a movable object (not :attr:`~app.maps.model.SemanticMap.fixed`)
  stands within about that std of where the map drew it (furniture is pushed about).
  A place error s seen from d metres turns the bearing by about s / d, so the object's
  bearing error has variance 1 / kappa + s^2 / d^2: a von Mises of concentration
  kappa * r, r = d^2 / (d^2 + kappa s^2), with its own normalisation. Far away this is
  the class's kappa; up close a moved chair no longer pins the pose, where at the bare
  kappa a pose a metre off that puts the chair where it is seen would win
  (:func:`spread_match`).

All likelihoods are relative to the von Mises peak, so a perfect match scores 0 in
log space; only differences between particles matter to the filter.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.localization.config import NARROW_CAMERA_FOV_DEG, FilterConfig
from app.localization.types import Detection
from app.maps.model import SemanticMap


def scaled_bessel_i0(kappa: float) -> float:
    """I0(kappa) * exp(-kappa), stable for large kappa (asymptotic series above 30)."""
    if kappa < 30.0:
        return float(np.i0(kappa) * np.exp(-kappa))
    return float(
        (1.0 + 1.0 / (8.0 * kappa) + 9.0 / (128.0 * kappa**2)) / np.sqrt(2 * np.pi * kappa)
    )


#: A spread object's r (:func:`spread_match`) is at least this (a particle on the object),
#: and its normalisation term at least SPREAD_MIN_NORM (in cosine units): whatever the
#: class's kappa, a visible object's match stays above -1.5, where "no candidate" begins
#: (sensor_kernel.NO_MATCH); for kappa of a few degrees' std the bound never binds.
SPREAD_MIN_R = 1e-12
SPREAD_MIN_NORM = -0.25


def object_spread_sq(semantic_map: SemanticMap, config: FilterConfig) -> NDArray[np.float64]:
    """Each object's squared place std (m^2) as :func:`spread_match` takes it:
    ``config.object_spread_m`` squared for a movable object, 0 for a fixed one (a door,
    a window), shape (objects,). Times the class's likelihood share
    (:meth:`FilterConfig.likelihood_share`): where a steady bias already widens the
    class's bearing variance to 1 / (share kappa), the place's s^2 / d^2 adds to that
    variance, not to the bare noise's."""
    s = config.object_spread_m

    def make() -> NDArray[np.float64]:
        if s <= 0.0:
            return np.zeros(semantic_map.object_count)
        share = np.array([config.likelihood_share(c) for c in semantic_map.classes])
        spread = s * s * share[semantic_map.object_class]
        return np.where(semantic_map.fixed, 0.0, spread).astype(np.float64)

    # Kept with the map: the fit check asks for it every frame.
    return semantic_map.derived_value(("object_spread", s, *_share_key(config)), make)


def _share_key(config: FilterConfig) -> tuple[object, ...]:
    """What :meth:`FilterConfig.likelihood_share` and each class's std depend on, as a
    key of values kept with the map."""
    per_class = tuple(config.class_bearing_std_deg.items())
    narrow = config.fov_deg < NARROW_CAMERA_FOV_DEG
    return config.bearing_std_deg, per_class, config.likelihood_bias_deg, narrow


def spread_match(
    cos_err: NDArray[np.float64],
    d2: NDArray[np.float64],
    kappa: NDArray[np.float64],
    spread_sq: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The match (eq. 3's cosine) of an object whose place has std s (``spread_sq`` =
    s^2), seen at squared distance ``d2``, for a class of concentration ``kappa``: with r
    = d2 / (d2 + kappa s^2), 1 + r (cos - 1) + log(r) / (2 kappa), so that kappa (match -
    1) is the log-density of a von Mises of concentration kappa r relative to the peak
    of the class's own (for large kappa, I0e(kappa r) / I0e(kappa) = r^-1/2). The cosine
    itself where s = 0. Arrays broadcast; r and the normalisation are bounded below
    (SPREAD_MIN_R, SPREAD_MIN_NORM)."""
    ks = kappa * spread_sq
    r = np.maximum(d2 / np.maximum(d2 + ks, 1e-300), SPREAD_MIN_R)
    norm = np.maximum(np.log(r) / (2.0 * kappa), SPREAD_MIN_NORM)
    return np.where(spread_sq > 0.0, 1.0 + r * (cos_err - 1.0) + norm, cos_err)


@dataclass(frozen=True)
class Observation:
    """One frame's usable detections, grouped by class, as flat arrays.

    Detections of classes the map lacks, and detections with score 0, are dropped
    (they carry no information). Shapes: K detections, G classes, M member slots.

    Attributes:
        det_bearing: each detection's bearing, radians, shape (K,).
        det_cos, det_sin: cos and sin of each bearing, shape (K,).
        det_score: detection scores, shape (K,).
        det_group: class group of each detection, shape (K,).
        group_kappa: von Mises concentration per group, shape (G,).
        group_weight: 1 / size(O_i) per group (eq. 2), shape (G,), times the class's
            share of the log-likelihood that counts (FilterConfig.likelihood_share).
        group_log_floor: log of the relative clutter density eps * I0e(kappa), -inf
            when clutter is off, shape (G,).
        group_log_keep: log(1 - eps) (0 when clutter is off), shape (G,).
        member_start: group g's objects are members[member_start[g]:member_start[g+1]]
            (none when every object of the class is excluded, below).
        members: object indices, shape (M,): the map's objects of each group's class,
            less those the session excluded (taken for moved on a stale map,
            :meth:`app.localization.models.BearingSensorModel.exclude`).
        classes: class word per group.
        ignored: class words of dropped unknown-class detections.
    """

    det_bearing: NDArray[np.float64]
    det_cos: NDArray[np.float64]
    det_sin: NDArray[np.float64]
    det_score: NDArray[np.float64]
    det_group: NDArray[np.int64]
    group_kappa: NDArray[np.float64]
    group_weight: NDArray[np.float64]
    group_log_floor: NDArray[np.float64]
    group_log_keep: NDArray[np.float64]
    member_start: NDArray[np.int64]
    members: NDArray[np.int64]
    classes: tuple[str, ...]
    ignored: tuple[str, ...] = ()

    @property
    def empty(self) -> bool:
        """True when the frame carries no evidence at all."""
        return self.det_cos.size == 0


@functools.lru_cache(maxsize=256)
def _class_terms(std_rad: float, eps: float) -> tuple[float, float, float]:
    """A class's concentration kappa, log clutter floor and log(1 - eps) (the same few
    values every frame, so kept)."""
    k = 1.0 / std_rad**2
    return k, (math.log(eps * scaled_bessel_i0(k)) if eps > 0.0 else -math.inf), math.log1p(-eps)


#: A frame's class groups: kappa, log floor and log keep per group, then member_start
#: and members (:class:`Observation`'s fields of those names), and each group's share of
#: its log-likelihood that counts (:meth:`FilterConfig.likelihood_share`).
_Layout = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]  # fmt: skip  # noqa: E501


def _class_layout(
    semantic_map: SemanticMap,
    config: FilterConfig,
    classes: tuple[str, ...],
    eps: float,
    excluded: tuple[int, ...] = (),
) -> _Layout:
    """The per-group arrays of :func:`prepare_observation` that do not depend on the
    detections themselves, only on which classes were seen (and which objects are
    ``excluded``, sorted); kept with the map (:meth:`SemanticMap.derived_value`), shared
    by every frame with the same classes and config terms. Nothing writes into an
    observation's arrays."""

    def make() -> _Layout:
        kappa, floor, keep, starts, share = [], [], [], [0], []
        members: list[int] = []
        for cls in classes:
            k, log_floor, log_keep = _class_terms(config.bearing_std_rad(cls), eps)
            kappa.append(k)
            floor.append(log_floor)
            keep.append(log_keep)
            members.extend(o for o in semantic_map.class_members[cls].tolist() if o not in excluded)
            starts.append(len(members))
            share.append(config.likelihood_share(cls))
        return (
            np.array(kappa, dtype=np.float64),
            np.array(floor, dtype=np.float64),
            np.array(keep, dtype=np.float64),
            np.array(starts, dtype=np.int64),
            np.array(members, dtype=np.int64),
            np.array(share, dtype=np.float64),
        )

    key = ("observation", classes, eps, *_share_key(config), excluded)
    return semantic_map.derived_value(key, make)


def prepare_observation(
    detections: Sequence[Detection],
    semantic_map: SemanticMap,
    config: FilterConfig,
    excluded: tuple[int, ...] = (),
) -> Observation:
    """Group a frame's detections by class into an :class:`Observation`; the objects
    ``excluded`` (sorted indices) explain none of them."""
    by_class: dict[str, list[Detection]] = {}
    ignored: list[str] = []
    for d in detections:
        if d.cls not in semantic_map.class_members:
            ignored.append(d.cls)
            continue
        if d.score <= 0.0:
            continue
        by_class.setdefault(d.cls, []).append(d)
    classes = tuple(sorted(by_class))
    bearing_l, score_l, group_l, weight = [], [], [], []
    for g, cls in enumerate(classes):
        dets = by_class[cls]
        for d in dets:
            bearing_l.append(float(d.bearing_rad))
            score_l.append(min(float(d.score), 1.0))
            group_l.append(g)
        weight.append(1.0 / len(dets))
    bearing = np.array(bearing_l, dtype=np.float64)
    return _assemble(
        bearing,
        np.cos(bearing),
        np.sin(bearing),
        np.array(score_l, dtype=np.float64),
        np.array(group_l, dtype=np.int64),
        np.array(weight, dtype=np.float64),
        classes,
        tuple(ignored),
        semantic_map,
        config,
        excluded,
    )


def _assemble(
    bearing: NDArray[np.float64],
    cos: NDArray[np.float64],
    sin: NDArray[np.float64],
    score: NDArray[np.float64],
    group: NDArray[np.int64],
    weight: NDArray[np.float64],
    classes: tuple[str, ...],
    ignored: tuple[str, ...],
    semantic_map: SemanticMap,
    config: FilterConfig,
    excluded: tuple[int, ...] = (),
) -> Observation:
    """An observation from its detections' arrays and its classes: the class groups'
    arrays come from the map (:func:`_class_layout`)."""
    eps = config.floor_prob if config.clutter else 0.0
    kappa, floor, keep, starts, members, share = _class_layout(
        semantic_map, config, classes, eps, excluded
    )
    return Observation(
        det_bearing=bearing,
        det_cos=cos,
        det_sin=sin,
        det_score=score,
        det_group=group,
        group_kappa=kappa,
        group_weight=weight * share if config.likelihood_bias_deg else weight,
        group_log_floor=floor,
        group_log_keep=keep,
        member_start=starts,
        members=members,
        classes=classes,
        ignored=ignored,
    )


#: The per-detection arrays :func:`observation_columns` keeps: field and dtype.
_DETECTION_FIELDS: dict[str, Any] = {
    "det_bearing": np.float64,
    "det_cos": np.float64,
    "det_sin": np.float64,
    "det_score": np.float64,
    "det_group": np.int64,
}


def observation_columns(observations: Sequence[Observation]) -> dict[str, Any]:
    """Observations as the few values they are made of, for a checkpoint: their
    detections' arrays joined end to end (bearings, their cosines and sines, scores,
    class groups), how many detections each has, and each one's classes and ignored
    class words. The class groups' arrays are left out: they follow from the classes
    and the map, and :func:`observations_from_columns` takes them from there. Half the
    arrays, and a third of the time, of storing every field
    (:func:`~app.state.to_columns`)."""
    return {
        # (the empty array first gives the dtype when there are no observations)
        **{
            f: np.concatenate([np.empty(0, dtype), *(getattr(o, f) for o in observations)])
            for f, dtype in _DETECTION_FIELDS.items()
        },
        "counts": np.array([o.det_bearing.size for o in observations], dtype=np.int64),
        "classes": [o.classes for o in observations],
        "ignored": [o.ignored for o in observations],
    }


def observations_from_columns(
    columns: Mapping[str, Any],
    semantic_map: SemanticMap,
    config: FilterConfig,
    excluded: tuple[int, ...] = (),
) -> list[Observation]:
    """The observations :func:`observation_columns` was given, on the map and with the
    configuration they were made with (each array a slice of one writable copy), the
    objects ``excluded`` now explaining none of them."""
    bearing, cos, sin, score, group = (
        np.array(columns[f], dtype=dtype) for f, dtype in _DETECTION_FIELDS.items()
    )
    counts = np.asarray(columns["counts"]).tolist()
    out = []
    start = 0
    for count, classes, ignored in zip(counts, columns["classes"], columns["ignored"], strict=True):
        part = slice(start, start + count)
        start += count
        # Each class's detections weigh 1 / their number (eq. 2), as prepare_observation
        # divides.
        weight = 1.0 / np.bincount(group[part], minlength=len(classes)).astype(np.float64)
        observation = _assemble(
            bearing[part],
            cos[part],
            sin[part],
            score[part],
            group[part],
            weight,
            tuple(classes),
            tuple(ignored),
            semantic_map,
            config,
            excluded,
        )
        out.append(observation)
    return out


def candidate_mask(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    objects: NDArray[np.int64],
    semantic_map: SemanticMap,
    config: FilterConfig,
    visible_rows: NDArray[np.bool_] | None,
) -> NDArray[np.bool_]:
    """Which of ``objects`` each particle could see, shape (N, len(objects)).

    With ``visibility`` off every object is a candidate (the paper's model).
    ``visible_rows`` are the particles' rows of the visibility grid, shape (N, objects).
    """
    n = x.shape[0]
    if not config.visibility:
        return np.ones((n, objects.size), dtype=bool)
    ok = (
        np.ones((n, objects.size), dtype=bool) if visible_rows is None else visible_rows[:, objects]
    )
    dx = semantic_map.object_xy[objects, 0][None, :] - x[:, None]
    dy = semantic_map.object_xy[objects, 1][None, :] - y[:, None]
    if config.fov_deg < 360.0:
        dist = np.hypot(dx, dy) + 1e-12
        centre = theta + np.radians(config.fov_centre_deg)  # the field's middle
        forward = (np.cos(centre)[:, None] * dx + np.sin(centre)[:, None] * dy) / dist
        ok &= forward >= np.cos(np.radians(config.fov_deg) / 2.0)
    if config.max_range_m is not None:
        ok &= dx * dx + dy * dy <= config.max_range_m**2
    return ok


def match_detections(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    obs: Observation,
    semantic_map: SemanticMap,
    config: FilterConfig,
    visible_rows: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Eq. (3): each detection's best candidate object at each particle, plain numpy.

    The one implementation of the paper's maximum-likelihood correspondence: among the
    objects of the detection's class that the particle could see (:func:`candidate_mask`),
    the one whose direction is closest to the detected bearing (the largest cosine of
    the bearing error; for a movable object with ``config.object_spread_m``, the
    widened match of :func:`spread_match`).

    Returns:
        (best, index), each shape (K, N), detections in the observation's order: the
        best cosine of the bearing error and the object's index; -inf and -1 where no
        object of the class is a candidate.
    """
    n = x.shape[0]
    if obs.empty:
        return np.full((0, n), -np.inf), np.full((0, n), -1, dtype=np.int64)
    # Every member object of every detected class at once, shape (N, M), then every
    # detection against the members of its own class, shape (K, N, M).
    objs = obs.members
    member_group = np.repeat(np.arange(obs.group_kappa.size), np.diff(obs.member_start))
    dx = semantic_map.object_xy[objs, 0][None, :] - x[:, None]
    dy = semantic_map.object_xy[objs, 1][None, :] - y[:, None]
    dist = np.hypot(dx, dy) + 1e-12
    cos_t = np.cos(theta)[:, None]
    sin_t = np.sin(theta)[:, None]
    # Unit vector towards each object in the particle's body frame.
    bx = (cos_t * dx + sin_t * dy) / dist
    by = (-sin_t * dx + cos_t * dy) / dist
    cand = candidate_mask(x, y, theta, objs, semantic_map, config, visible_rows)
    own = member_group[None, None, :] == obs.det_group[:, None, None]
    match = obs.det_cos[:, None, None] * bx[None] + obs.det_sin[:, None, None] * by[None]
    if config.object_spread_m > 0.0:
        # A movable object's place is uncertain: its match is widened up close.
        spread = object_spread_sq(semantic_map, config)[objs]
        kappa = obs.group_kappa[member_group]
        match = spread_match(match, (dx * dx + dy * dy)[None], kappa[None, None, :], spread)
    cos_err = np.where(own & cand[None, :, :], match, -np.inf)
    j = np.argmax(cos_err, axis=2)
    best = np.take_along_axis(cos_err, j[:, :, None], axis=2)[:, :, 0]
    index = np.where(np.isfinite(best), objs[j], -1)
    return best, index


def log_likelihood_reference(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    theta: NDArray[np.float64],
    obs: Observation,
    semantic_map: SemanticMap,
    config: FilterConfig,
    visible_rows: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """Per-particle log P(Z | s, M) of eqs. (2)-(3), plain numpy, shape (N,).

    The readable reference; :mod:`app.localization.sensor_kernel` computes the same
    numbers faster and the tests hold the two together.
    """
    total = np.zeros(x.shape[0], dtype=np.float64)
    best, _ = match_detections(x, y, theta, obs, semantic_map, config, visible_rows)  # eq. (3)
    for k in range(obs.det_cos.size):
        g = obs.det_group[k]
        # von Mises log-density relative to its peak, mixed with the clutter floor
        log_p = np.logaddexp(
            obs.group_kappa[g] * (best[k] - 1.0) + obs.group_log_keep[g], obs.group_log_floor[g]
        )
        # score tempering (P^w) and the class exponent 1/size(O_i), eq. (2)
        total += obs.group_weight[g] * obs.det_score[k] * log_p
    return total


@njit(cache=True, nogil=True, error_model="numpy")
def _residuals(
    x, y, theta, visible, check_fov, cos_half_fov, fov_centre, max_range_sq,
    obj_xy, obj_spread_sq, det_bearing, det_group, group_kappa, member_start, members, out,
):  # fmt: skip  # pragma: no cover - compiled
    c = np.cos(theta + fov_centre)
    s = np.sin(theta + fov_centre)
    two_pi = 2.0 * np.pi
    for k in range(det_bearing.shape[0]):
        g = det_group[k]
        best = np.inf
        for j in range(member_start[g], member_start[g + 1]):
            o = members[j]
            dx = obj_xy[o, 0] - x
            dy = obj_xy[o, 1] - y
            d2 = dx * dx + dy * dy
            if not visible[o] or d2 > max_range_sq:
                continue
            if check_fov and (c * dx + s * dy) / (np.sqrt(d2) + 1e-12) < cos_half_fov:
                continue
            err = det_bearing[k] - (np.arctan2(dy, dx) - theta)
            # In stds of the object's bearing: kappa, or a movable object's kappa r
            # (spread_match).
            kappa = group_kappa[g]
            if obj_spread_sq[o] > 0.0:
                kappa = kappa * max(d2 / (d2 + kappa * obj_spread_sq[o]), SPREAD_MIN_R)
            best = min(best, abs(err - two_pi * np.round(err / two_pi)) * np.sqrt(kappa))
        out[k] = best


def normalized_residuals(
    x: float,
    y: float,
    theta: float,
    obs: Observation,
    semantic_map: SemanticMap,
    config: FilterConfig,
    visible_row: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """Each detection's bearing error at one pose, in units of its class's std (a movable
    object's widened by its place's spread, :func:`spread_match`), shape (K,).

    The error is to the best-matching visible object of the detection's class (eq. 3);
    a detection nothing visible explains gets +inf. Used to check that a converged
    estimate actually explains what the camera sees. ``visible_row`` (shape (N,)) is
    the pose's row of the visibility grid; computed exactly when not given.
    """
    out = np.empty(obs.det_cos.size)  # np.full's values, without its Python wrapper
    out.fill(np.inf)
    if obs.empty:
        return out
    n_obj = semantic_map.object_count
    if not config.visibility:
        visible = np.ones(n_obj, dtype=np.bool_)
    elif visible_row is None:
        visible = semantic_map.line_of_sight(np.array([[x, y]], dtype=np.float64))[0]
    else:
        visible = np.ascontiguousarray(visible_row, dtype=np.bool_)
    check_fov = config.visibility and config.fov_deg < 360.0
    max_range = config.max_range_m if config.visibility else None
    _residuals(
        float(x), float(y), float(theta), visible, check_fov,
        float(np.cos(np.radians(config.fov_deg) / 2.0)),
        float(np.radians(config.fov_centre_deg)),
        np.inf if max_range is None else float(max_range) ** 2,
        semantic_map.object_xy.reshape(-1, 2), object_spread_sq(semantic_map, config),
        obs.det_bearing, obs.det_group, obs.group_kappa, obs.member_start, obs.members, out,
    )  # fmt: skip
    return out
