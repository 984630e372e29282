"""What the compilation engine needs from the orientation: a small adapter.

The engine (``apygis.compile.engine``) is pure: it never reads files or
talks to motors. It asks a :class:`Geometry` four things:

* ``ground(x_mm, y_mm) -> (X, Y)``: the map transform, tablet millimetres to
  ground metres;
* ``tablet(X, Y) -> (x_mm, y_mm)``: its inverse (the simulator drives the mark
  to ground positions through it);
* ``correct_z(X, Y, z_model) -> Z``: the residual height correction
  ``Z = z_model + dpZ(X, Y)``, ``dpZ = A x + B y + C x y + D``;
* ``plates(X, Y, Z) -> tuple | None``: the four plate motor positions (steps:
  left x, left y, right x, right y) that keep both photos in register with
  the mark, or None when no photos are oriented (compiling on the map only);

and ``height_step_m``, the height change of one UP/DOWN press, which follows
the plate-step resolution.

:class:`PlaneGeometry` is the map-only case (a conformal tablet transform,
no photos). :mod:`apygis.compile.oriented` builds an oriented one from an
orientation file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

__all__ = ["Geometry", "PlaneGeometry"]


@runtime_checkable
class Geometry(Protocol):
    """What the engine asks of an orientation; see the module docstring."""

    height_step_m: float

    def ground(self, x_mm: float, y_mm: float) -> tuple[float, float]: ...

    def tablet(self, X: float, Y: float) -> tuple[float, float]: ...

    def correct_z(self, X: float, Y: float, z_model: float) -> float: ...

    def plates(self, X: float, Y: float, Z: float) -> tuple[int, int, int, int] | None: ...


@dataclass(frozen=True)
class PlaneGeometry:
    """Map only: ``X = E0 + s (cos a x - sin a y)``, ``Y = N0 + s (sin a x + cos a y)``.

    ``scale`` is the map scale denominator: one tablet millimetre is
    ``scale / 1000`` ground metres. ``rotation_rad`` turns tablet axes into
    ground axes (counter-clockwise). No photos: ``plates`` is None.

    >>> g = PlaneGeometry(2683000.0, 1247000.0, scale=5000)
    >>> g.ground(10.0, 20.0)
    (2683050.0, 1247100.0)
    >>> g.tablet(2683050.0, 1247100.0)
    (10.0, 20.0)
    """

    e0: float
    n0: float
    scale: float = 5000.0
    rotation_rad: float = 0.0
    height_step_m: float = 0.1

    def ground(self, x_mm, y_mm):
        s = self.scale / 1000.0
        c, n = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        return (self.e0 + s * (c * x_mm - n * y_mm), self.n0 + s * (n * x_mm + c * y_mm))

    def tablet(self, X, Y):
        s = self.scale / 1000.0
        c, n = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        dx, dy = (X - self.e0) / s, (Y - self.n0) / s
        return (c * dx + n * dy, -n * dx + c * dy)

    def correct_z(self, X, Y, z_model):
        return z_model

    def plates(self, X, Y, Z):
        return None
