"""The engine's :class:`~apygis.compile.geometry.Geometry` from an orientation file.

* ``ground`` / ``tablet``: the map transform of the orientation (conformal,
  affine or bilinear; tablet millimetres <-> ground metres).
* ``correct_z``: the bilinear residual height correction, if fitted.
* ``plates``: the real-time loop of the first two photos (left, right) with
  their motor calibrations: motor positions left x, left y, right x, right y.
  Without two oriented photos with motors, the session compiles on the map
  only and ``plates`` is None.
* ``height_step_m``: the height change that moves the x-parallax between the
  two photos by one motor step, at the model's centre (below the middle of
  the base, at the ground height ``Zo - c / s``): one UP/DOWN press is the
  smallest height the plates can show. Without photos, ``default_step_m``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from apygis.errors import OrientationError

if TYPE_CHECKING:
    from apygis.orient.realtime import RealtimeLoop

__all__ = ["OrientedGeometry"]


class OrientedGeometry:
    """See the module docstring. ``orientation`` is an ``apygis.orient.io.Orientation``."""

    def __init__(self, orientation, default_step_m: float = 0.1):
        from apygis.orient.realtime import RealtimeLoop

        if orientation.map_transform is None:
            raise OrientationError(
                "the orientation file has no map orientation: run 'apygis orient map' first"
            )
        self.orientation = orientation
        self._t = orientation.map_transform
        self._hc = orientation.height_correction
        self.loop: RealtimeLoop | None = None
        self.height_step_m = float(default_step_m)
        photos = orientation.photos
        if len(photos) >= 2:
            try:
                ml = orientation.motor(photos[0].photo_id)
                mr = orientation.motor(photos[1].photo_id)
            except KeyError:
                ml = mr = None
            if ml is not None:
                loop = RealtimeLoop(photos[0], photos[1], ml, mr)
                self.loop = loop
                self.height_step_m = self._plate_height_step(loop, photos[0], photos[1], ml)

    def _plate_height_step(self, loop: RealtimeLoop, left, right, motors) -> float:
        el, er = left.exterior, right.exterior
        H = left.interior.focal_mm / abs(left.sx_mm_per_m)
        X, Y, Z = (el.Xo + er.Xo) / 2, (el.Yo + er.Yo) / 2, el.Zo - H
        a, b = loop.update(X, Y, Z), loop.update(X, Y, Z + 1.0)
        dp_mm_per_m = abs((b.px_left - b.px_right) - (a.px_left - a.px_right))
        if not dp_mm_per_m > 0:
            return self.height_step_m
        return (motors.step_um / 1000.0) / dp_mm_per_m

    def ground(self, x_mm, y_mm):
        return self._t.forward_xy(x_mm, y_mm)

    def tablet(self, X, Y):
        x, y = self._t.inverse(np.array([X, Y], dtype=float))
        return float(x), float(y)

    def correct_z(self, X, Y, z_model):
        if self._hc is None:
            return z_model
        return float(self._hc.correct(X, Y, z_model))

    def plates(self, X, Y, Z):
        if self.loop is None:
            return None
        u = self.loop.update(X, Y, Z)
        return (u.steps_left_x, u.steps_left_y, u.steps_right_x, u.steps_right_y)
