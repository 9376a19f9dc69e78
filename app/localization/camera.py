"""Phone cameras: from a detector's pixel box to a bearing, and back.

A detector on a phone reports boxes in image columns; the filter needs the bearing of
the object's centre relative to the person's forward direction (counter-clockwise
positive, docs/API.md "Camera and boxes"). Image columns ``u`` grow to the right, so a
box left of the image centre has a positive bearing:

* **equirectangular** (a 360-degree image ``W`` pixels wide): the columns are linear in
  angle, ``bearing = 360 * (W/2 - u) / W`` degrees. The image wraps around: a box with
  ``u_min > u_max`` runs over the right edge and continues at the left one.
* **pinhole** (an ordinary phone camera): ``bearing = atan((cx - u) / fx)`` with the
  focal length ``fx`` and the principal point ``cx`` in pixels; the field of view
  spans the image's columns ``0..W``.

``yaw_offset_deg`` is the camera's forward direction relative to the body's forward,
counter-clockwise positive (a phone worn on a strap pointing a little left has a
positive offset); it is added to every bearing. The box's horizontal centre is taken
as the object's centre.

Everything here is plain arithmetic on floats: no I/O, no wire models.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from app.maps.geometry import wrap_deg

CameraKind = Literal["equirectangular", "pinhole"]


class BoxError(ValueError):
    """A pixel box that does not fit the camera; the message says why."""


@dataclass(frozen=True)
class Camera:
    """One camera model (degrees and pixels, as the client gives them).

    Attributes:
        model: ``equirectangular`` (360 degrees) or ``pinhole``.
        width_px: image width in pixels.
        fx_px, cx_px: pinhole focal length and principal point column (pixels);
            ignored for an equirectangular camera.
        yaw_offset_deg: camera forward relative to body forward, CCW positive.
    """

    model: CameraKind
    width_px: float
    fx_px: float = 0.0
    cx_px: float = 0.0
    yaw_offset_deg: float = 0.0

    def __post_init__(self) -> None:
        if not self.width_px > 0:
            raise ValueError(f"width_px must be positive, got {self.width_px}")
        if self.model == "pinhole" and not self.fx_px > 0:
            raise ValueError(f"a pinhole camera needs fx_px > 0, got {self.fx_px}")
        if self.model not in ("equirectangular", "pinhole"):
            raise ValueError(f"unknown camera model {self.model!r}")

    # ---------------------------------------------------------------- geometry
    def _column_bearing_deg(self, u: float) -> float:
        """Bearing of image column ``u`` in the camera's own frame (no yaw), degrees."""
        if self.model == "equirectangular":
            return 360.0 * (self.width_px / 2.0 - u) / self.width_px
        return math.degrees(math.atan((self.cx_px - u) / self.fx_px))

    @property
    def fov_deg(self) -> float:
        """Horizontal field of view, degrees (360 for an equirectangular image)."""
        if self.model == "equirectangular":
            return 360.0
        return self._column_bearing_deg(0.0) - self._column_bearing_deg(self.width_px)

    @property
    def fov_centre_deg(self) -> float:
        """Direction of the middle of the field of view relative to the body, degrees.

        Zero for a centred pinhole camera without yaw; an off-centre principal point
        shifts it (the field spans ``atan(cx/fx)`` to the left and ``atan((W-cx)/fx)``
        to the right), and the yaw offset turns it.
        """
        if self.model == "equirectangular":
            return 0.0
        left = self._column_bearing_deg(0.0)
        right = self._column_bearing_deg(self.width_px)
        return wrap_deg((left + right) / 2.0 + self.yaw_offset_deg)

    def box_centre_px(self, u_min_px: float, u_max_px: float) -> float:
        """The box's horizontal centre column, across the seam of a 360-degree image.

        Raises:
            BoxError: a column outside ``0..width_px``, or ``u_min > u_max`` on a
                pinhole image (only a 360-degree image wraps).
        """
        w = self.width_px
        for name, u in (("u_min_px", u_min_px), ("u_max_px", u_max_px)):
            if not (math.isfinite(u) and 0.0 <= u <= w):
                raise BoxError(f"box.{name}: {u} is outside the image (0 to {w:g} pixels)")
        if u_min_px <= u_max_px:
            return (u_min_px + u_max_px) / 2.0
        if self.model != "equirectangular":
            raise BoxError(
                f"box: u_min_px {u_min_px} is right of u_max_px {u_max_px}; only a 360-degree "
                "(equirectangular) image wraps around its edge"
            )
        # Wraps the seam: the box runs from u_min to the right edge, then 0 to u_max.
        return ((u_min_px + u_max_px + w) / 2.0) % w

    def box_bearing_deg(self, u_min_px: float, u_max_px: float) -> float:
        """Bearing of a box's horizontal centre relative to the body, (-180, 180] degrees."""
        u = self.box_centre_px(u_min_px, u_max_px)
        return wrap_deg(self._column_bearing_deg(u) + self.yaw_offset_deg)

    def column_of(self, bearing_deg: float) -> float | None:
        """The image column where a body-frame bearing lands, or None if out of view."""
        b = wrap_deg(bearing_deg - self.yaw_offset_deg)
        if self.model == "equirectangular":
            return (self.width_px / 2.0 - b * self.width_px / 360.0) % self.width_px
        if abs(b) >= 90.0:
            return None
        u = self.cx_px - self.fx_px * math.tan(math.radians(b))
        return u if 0.0 <= u <= self.width_px else None

    def box_of(self, bearing_deg: float, width_deg: float) -> tuple[float, float] | None:
        """A box for an object seen at ``bearing_deg`` spanning ``width_deg`` of view.

        Centred on the object's column (so :meth:`box_bearing_deg` gives the bearing
        back); on a pinhole image cut at the image edges like a detector's box, on a
        360-degree image wrapped across the seam. None when the centre is out of view.
        """
        u = self.column_of(bearing_deg)
        if u is None:
            return None
        w = self.width_px
        if self.model == "equirectangular":
            half = min(width_deg, 359.0) / 360.0 * w / 2.0
            return ((u - half) % w, (u + half) % w)
        b = math.radians(wrap_deg(bearing_deg - self.yaw_offset_deg))
        # Half the box in pixels at that column: the angular width scaled by the local
        # pixels per radian, fx / cos^2(b).
        half = self.fx_px * math.radians(width_deg) / 2.0 / math.cos(b) ** 2
        return (max(0.0, u - half), min(w, u + half))
