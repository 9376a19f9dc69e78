"""A fix let go for doubt alone continues when it comes back (continuation.DOUBT_FRAMES,
GEOMETRY_DOUBT_FRAMES)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import app.localization.filter as filter_module
from app.localization.continuation import DOUBT_FRAMES, GEOMETRY_DOUBT_FRAMES
from app.localization.dilution import BearingGeometry
from app.localization.evidence import EvidenceTracker
from app.localization.filter import ParticleFilter
from app.localization.types import (
    Detection,
    Estimate,
    Hypothesis,
    InitialPose,
    Odometry,
    Pose,
)
from app.service import checkpoint
from app.simulation.venue import venue_map
from tests.helpers import told_at

VENUE = venue_map()
POSE = Pose(8.0, 3.0, math.pi / 2)


def _doubt_switch(monkeypatch: pytest.MonkeyPatch) -> dict[str, bool]:
    """A switch: while its ``"doubt"`` is True the evidence tracker gives the other
    places half the probability (every share the filter reads), else its own."""
    state = {"doubt": False}
    for name in ("alternative_share", "confirmed_share", "gain_share"):
        real = getattr(EvidenceTracker, name)
        monkeypatch.setattr(
            EvidenceTracker,
            name,
            property(lambda self, real=real: 0.5 if state["doubt"] else real.fget(self)),
        )
    return state


def _located_then_let_go(
    monkeypatch: pytest.MonkeyPatch, cause: str, through_a_checkpoint: bool = False
) -> tuple[tuple[str, ...], list[bool], list[float | None]]:
    """Standing at POSE through a 66-degree camera from a known start, a fix is told;
    then for three frames an alternative holds half the probability (``cause``
    "alternative"), the bearings' geometry bounds the place no closer than 6 m
    ("geometry"), or the camera reports three boxes nothing on the map explains
    ("junk"). Returns why the fix was let go, and converged and the radius on each of
    the GEOMETRY_DOUBT_FRAMES frames after (``through_a_checkpoint``: by a filter
    restored from a checkpoint taken then, as a worker taking the session over would)."""
    # The radius a first fix needs, lowered under this fix's (about 0.5 m): every gain
    # here is a wide one.
    monkeypatch.setattr(filter_module, "GAIN_PROTECTION_M", 0.3)
    state = _doubt_switch(monkeypatch)
    state["wide"] = False
    radius_m = BearingGeometry.radius_m
    monkeypatch.setattr(
        BearingGeometry,
        "radius_m",
        lambda self, *pose: 6.0 if state["wide"] else radius_m(self, *pose),
    )
    pf, seen, est = told_at(VENUE, POSE)
    still = Odometry(0.0, 0.0, 0.0)
    assert est.converged and est.protection_m is not None and est.protection_m > 0.3
    junk = [Detection("bench", b, 1.0) for b in (-0.4, 0.0, 0.4)]
    for _ in range(3):
        state["doubt"], state["wide"] = cause == "alternative", cause == "geometry"
        est = pf.step(still, junk if cause == "junk" else seen)
    state["doubt"] = state["wide"] = False
    assert not est.converged
    why = pf._gate.lost_because
    if through_a_checkpoint:
        data = checkpoint.pack({"format": checkpoint.FORMAT_VERSION, "filter": pf.checkpoint()})
        pf = ParticleFilter(VENUE, pf.config, rng=np.random.default_rng(99))
        pf.restore(checkpoint.unpack(data)["filter"])
    converged, radius = [], []
    for _ in range(GEOMETRY_DOUBT_FRAMES):
        est = pf.step(still, seen)
        converged.append(est.converged)
        radius.append(est.protection_m)
    return why, converged, radius


@pytest.mark.parametrize("through_a_checkpoint", [False, True])
@pytest.mark.parametrize(
    ("cause", "why", "within"),
    [
        ("alternative", ("alternative",), DOUBT_FRAMES),
        ("geometry", ("weak geometry",), GEOMETRY_DOUBT_FRAMES),
    ],
)
def test_a_fix_let_go_for_doubt_alone_is_taken_up_without_a_narrow_radius(
    monkeypatch: pytest.MonkeyPatch,
    through_a_checkpoint: bool,
    cause: str,
    why: tuple[str, ...],
    within: int,
) -> None:
    """An alternative that gained probability, or a geometry bound grown past the
    hold's: taken up within the doubt's window (DOUBT_FRAMES, GEOMETRY_DOUBT_FRAMES)
    at a radius a first fix could not have."""
    let_go, converged, radius = _located_then_let_go(monkeypatch, cause, through_a_checkpoint)
    assert let_go == why
    assert any(converged[:within]), f"the fix was not taken up within {within} frames"
    gained = radius[converged.index(True)]
    assert gained is not None and gained > 0.3


def test_a_fix_let_go_for_what_the_camera_saw_needs_a_narrow_radius_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    why, converged, _ = _located_then_let_go(monkeypatch, "junk")
    assert why and "alternative" not in why
    assert not any(converged)


def _spread(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every frame's cluster (filter.estimate_pose) as a held fix may be and a first
    gain may not: all the weight, but 0.35 m wide along x (the clustering's converged
    asks at most 0.25 m, the gate's hold at most 0.5 m)."""
    real = filter_module.estimate_pose

    def spread(*args: object, **kwargs: object) -> Estimate:
        e = real(*args, **kwargs)  # type: ignore[arg-type]
        top = e.hypotheses[0] if e.hypotheses else None
        if top is None:
            return e
        hyps = (Hypothesis(top.x, top.y, top.theta_rad, 1.0, top.std_xy_m), *e.hypotheses[1:])
        return Estimate(
            e.x, e.y, e.theta_rad, 0.35, e.std_y_m, e.std_theta_rad, False, hyps,
            e.n_particles, e.ess, e.protection_m,
        )  # fmt: skip

    monkeypatch.setattr(filter_module, "estimate_pose", spread)


def test_a_fix_let_go_for_doubt_is_taken_up_with_the_cluster_a_held_fix_keeps(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The alternative's doubt gone, a cloud as wide as a held fix may be (not as tight
    as a first gain's) is the fix again within the doubt's window; without the doubt
    (a first gain, here from a known start) it is not."""
    monkeypatch.setattr(filter_module, "GAIN_PROTECTION_M", 0.3)
    state = _doubt_switch(monkeypatch)
    pf, seen, est = told_at(VENUE, POSE)
    assert est.converged
    still = Odometry(0.0, 0.0, 0.0)
    _spread(monkeypatch)
    state["doubt"] = True
    for _ in range(3):
        est = pf.step(still, seen)
    state["doubt"] = False
    assert not est.converged and pf._gate.lost_because == ("alternative",)
    converged = [pf.step(still, seen).converged for _ in range(DOUBT_FRAMES)]
    assert any(converged), "the fix was not taken up again within the doubt's window"

    first = ParticleFilter(
        VENUE,
        pf.config,
        rng=np.random.default_rng(3),
        initial_pose=InitialPose(POSE.x, POSE.y, POSE.theta_rad, 0.1, 0.05),
    )
    assert not any(first.step(still, seen).converged for _ in range(DOUBT_FRAMES))
