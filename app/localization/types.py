"""Plain value types shared by the filter and its callers.

Internally every angle is in radians and every length in metres; the names say so.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class Odometry:
    """Motion since the previous frame, expressed in the previous body frame.

    Body frame: +x forward, +y left; ``turn_rad`` counter-clockwise positive.
    """

    forward_m: float = 0.0
    left_m: float = 0.0
    turn_rad: float = 0.0


@dataclass(frozen=True, slots=True)
class Detection:
    """One object detection: what, in which direction, how sure.

    ``bearing_rad`` is relative to the person's forward direction, counter-clockwise
    positive (left is +pi/2). ``score`` is in [0, 1]; 0 carries no information.
    """

    cls: str
    bearing_rad: float
    score: float = 1.0


@dataclass(frozen=True, slots=True)
class Pose:
    """A pose in the map frame: metres and radians (theta CCW from +x)."""

    x: float
    y: float
    theta_rad: float


@dataclass(frozen=True, slots=True)
class InitialPose:
    """A known start: mean pose and standard deviations."""

    x: float
    y: float
    theta_rad: float
    std_xy_m: float = 0.3
    std_theta_rad: float = 0.2


@dataclass(frozen=True, slots=True)
class Hypothesis:
    """One mode of the belief with the share of the weight it holds (0..1)."""

    x: float
    y: float
    theta_rad: float
    weight: float
    std_xy_m: float = 0.0


@dataclass(frozen=True, slots=True)
class Estimate:
    """What the filter believes after a step.

    ``x, y, theta_rad`` and the standard deviations describe the heaviest cluster.
    ``converged`` is true only when one tight cluster holds most of the weight.
    ``hypotheses`` lists up to three modes, heaviest first (clusters of the particles
    and alternatives kept alive by :mod:`~app.localization.evidence`).
    ``protection_m`` is the radius around (x, y) that holds the true position with at
    least 99 % probability under the whole belief; None while not converged.
    """

    x: float
    y: float
    theta_rad: float
    std_x_m: float
    std_y_m: float
    std_theta_rad: float
    converged: bool
    hypotheses: tuple[Hypothesis, ...] = field(default_factory=tuple)
    n_particles: int = 0
    ess: float = 0.0
    protection_m: float | None = None

    # dataclasses.replace costs about 2.7 us a call (it walks the fields by name); the
    # filter changes these two fields of every frame's estimate, so they are spelt out
    # (tests/localization/test_types.py holds them to replace for every field).
    def with_converged(self, converged: bool) -> Estimate:
        """This estimate with ``converged`` set."""
        return Estimate(
            self.x, self.y, self.theta_rad, self.std_x_m, self.std_y_m, self.std_theta_rad,
            converged, self.hypotheses, self.n_particles, self.ess, self.protection_m,
        )  # fmt: skip

    def with_protection(self, protection_m: float | None) -> Estimate:
        """This estimate with ``protection_m`` set."""
        return Estimate(
            self.x, self.y, self.theta_rad, self.std_x_m, self.std_y_m, self.std_theta_rad,
            self.converged, self.hypotheses, self.n_particles, self.ess, protection_m,
        )  # fmt: skip
