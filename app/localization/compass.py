"""The phone's compass as a measurement of the particles' heading, heavy-tailed.

A phone compass indoors is often right within its stated accuracy and sometimes far
off: steel beams, radiators and electric cabinets bend the magnetic field by 30-90
degrees for metres at a time. The measurement model is therefore a mixture

    p(h | theta) = (1 - eps) * vonMises(h - theta; kappa) + eps / (2 pi)

with kappa = 1 / std^2 (std as the client reports it, floored at ``MIN_STD_DEG``) and
an outlier share ``eps``. Near the truth it sharpens the heading like any bearing;
far from it the uniform part takes over and the likelihood goes flat, so a compass
that reads 60 degrees off pulls the belief only weakly (the ratio between a particle
at the reading and one 60+ degrees away is bounded by about 1 / (eps * I0e(kappa)))
while the bearings to objects, far sharper, keep the fix.

As in the sensor model (app.localization.sensor) the log-likelihood is relative to the
von Mises peak: a particle pointing exactly where the compass says scores 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.localization.sensor import scaled_bessel_i0

#: Share of compass readings assumed to be disturbed (anywhere on the circle).
OUTLIER_SHARE = 0.3
#: A std below this is not believed: phone compasses are rarely better indoors.
MIN_STD_DEG = 5.0


@dataclass(frozen=True, slots=True)
class CompassReading:
    """An absolute heading in the map frame (radians, CCW from +x) and its std (radians)."""

    heading_rad: float
    std_rad: float


def compass_log_likelihood(
    theta: NDArray[np.float64], reading: CompassReading, outlier_share: float = OUTLIER_SHARE
) -> NDArray[np.float64]:
    """log p(reading | theta) relative to the peak, for every particle heading, shape (N,).

    The mixture in the module docstring:
    ``log((1 - eps) * exp(kappa * (cos(h - theta) - 1)) + eps * I0e(kappa))``.
    """
    heading, kappa, log_keep, log_floor = compass_terms(reading, outlier_share)
    vm = kappa * (np.cos(heading - theta) - 1.0) + log_keep
    return np.logaddexp(vm, log_floor)


def compass_terms(
    reading: CompassReading, outlier_share: float = OUTLIER_SHARE
) -> tuple[float, float, float, float]:
    """The mixture's constants: (heading, kappa, log(1 - eps), log(eps * I0e(kappa)))."""
    std = max(reading.std_rad, math.radians(MIN_STD_DEG))
    kappa = 1.0 / std**2
    log_keep = math.log1p(-outlier_share)
    log_floor = math.log(outlier_share * scaled_bessel_i0(kappa))
    return reading.heading_rad, kappa, log_keep, log_floor
