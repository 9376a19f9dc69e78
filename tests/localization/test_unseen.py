"""The unseen-object check: its compiled frame count against the vectorized numpy form."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from app.bench import CLASSES, generated_map
from app.localization.config import FilterConfig
from app.localization.sensor import prepare_observation
from app.localization.types import Detection
from app.localization.unseen import UnseenObjects
from app.maps.geometry import wrap_angle


def _numpy_counts(
    unseen: UnseenObjects, x: float, y: float, theta: float, obs, row
) -> tuple[np.ndarray, np.ndarray, int, int, np.ndarray]:
    """One frame counted as the vectorized numpy code did (before it was compiled)."""
    st, sm, cfg = unseen.settings, unseen.map, unseen.config
    index = {c: i for i, c in enumerate(sm.classes)}
    group_class = np.array([index[c] for c in obs.classes], dtype=np.int64)
    reported = unseen.reported.copy()
    reported[group_class] = True
    reach_m = unseen.reach_m.copy()
    dx, dy = sm.object_xy[:, 0] - x, sm.object_xy[:, 1] - y
    dist = np.hypot(dx, dy)
    bearing = wrap_angle(np.arctan2(dy, dx) - theta)
    cls = sm.object_class
    view = (dist <= st.near_m) & (dist >= st.min_m) & reported[cls]
    if row is not None and cfg.visibility:
        view &= row
    if cfg.fov_deg < 360.0:
        off_centre = np.abs(wrap_angle(bearing - np.radians(cfg.fov_centre_deg)))
        view &= off_centre <= np.radians(cfg.fov_deg) / 2.0 - st.margin_rad
    in_view = np.flatnonzero(view)
    same = cls[in_view][:, None] == group_class[obs.det_group][None, :]
    err = np.abs(wrap_angle(obs.det_bearing[None, :] - bearing[in_view][:, None]))
    within = st.cutoff_sigmas / np.sqrt(obs.group_kappa[obs.det_group])
    seen = np.zeros(sm.object_count, dtype=bool)
    seen[in_view] = (same & (err <= within[None, :])).any(axis=1)
    np.maximum.at(reach_m, cls[seen], dist[seen])
    reach = np.where(reach_m > 0.0, reach_m, reach_m.max())
    clear = view & (dist <= reach[cls])
    expected = st.decay * unseen.expected + clear
    seen_count = st.decay * unseen.seen + (clear & seen)
    missed = int(np.count_nonzero(clear & ~seen))
    return expected, seen_count, int(np.count_nonzero(clear)), missed, reach_m


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize(
    ("fov_deg", "centre_deg", "with_row"),
    [(360.0, 0.0, True), (90.0, 20.0, True), (180.0, 0.0, False)],
)
def test_compiled_frame_count_matches_numpy_to_the_bit(
    fov_deg: float, centre_deg: float, with_row: bool
) -> None:
    sm = generated_map(40, seed=2)
    cfg = replace(FilterConfig(), fov_deg=fov_deg, fov_centre_deg=centre_deg)
    unseen = UnseenObjects(sm, cfg)
    rng = np.random.default_rng(7)
    x, y = 6.0, 5.0
    answers = set()
    for frame in range(60):
        # A wandering pose (small steps, so the counts are not reset by a jump) and
        # detections: some aimed at objects (noisy), some of a class the map lacks.
        x = float(np.clip(x + rng.normal(0.0, 0.2), 0.5, 19.5))
        y = float(np.clip(y + rng.normal(0.0, 0.2), 0.5, 11.5))
        theta = float(rng.uniform(-4.0, 4.0))
        # From frame 40 on, one object only: the others in view go unreported.
        aims = rng.choice(sm.object_count, size=rng.integers(1, 8) if frame < 40 else 1)
        dets = [
            Detection(
                sm.class_of(int(i)),
                float(np.arctan2(*(sm.object_xy[i] - (x, y))[::-1]) - theta + rng.normal(0, 0.05)),
                float(rng.uniform(0.3, 1.0)),
            )
            for i in aims
        ] + [Detection(CLASSES[int(rng.integers(3))], float(rng.uniform(-np.pi, np.pi)), 0.5)]
        obs = prepare_observation(dets, sm, cfg)
        row = sm.visibility.row(x, y) if with_row else None
        want = _numpy_counts(unseen, x, y, theta, obs, row)
        unseen.update(x, y, theta, obs, row)
        got = (unseen.expected, unseen.seen, unseen.frame_expected, unseen.frame_missed)
        assert np.array_equal(_bits(got[0]), _bits(want[0]))
        assert np.array_equal(_bits(got[1]), _bits(want[1]))
        assert got[2:] == want[2:4]
        assert np.array_equal(_bits(unseen.reach_m), _bits(want[4]))
        # The kernel's answer to "contradicted" is the counts' (the property's formula).
        st = unseen.settings
        flagged = (got[0] >= st.min_expected) & (got[1] <= st.max_seen_share * got[0])
        assert unseen.contradicted == bool(flagged.any())
        answers.add(unseen.contradicted)
    assert unseen.expected.max() > 1.0  # objects were in clear view, some frames running
    if fov_deg == 360.0:  # the full view meets both answers (a narrow one may not)
        assert answers == {True, False}, answers
