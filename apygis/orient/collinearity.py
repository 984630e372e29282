"""Collinearity, superposition and the APY parallax conditions.

Conventions (axes, rotation order and sense, the sign of c, the elements
``a_ij``) are those of :mod:`apygis.orient.rotation`. Ground coordinates are in
metres, photo coordinates and the principal distance in millimetres.

The three conditions of the seed, with ``dX = X - Xo``, ``dY = Y - Yo``,
``dZ = Z - Zo``:

(a) collinearity::

        x - x0 = -c (a11 dX + a21 dY + a31 dZ) / (a13 dX + a23 dY + a33 dZ)
        y - y0 = -c (a12 dX + a22 dY + a32 dZ) / (a13 dX + a23 dY + a33 dZ)

(b) superposition of the map on the photo, ``sx`` and ``sy`` being the
    map-to-photo scale factors (photo millimetres per ground metre, signed)::

        x - x0 = -sx dX + px
        y - y0 = -sy dY + py

(c) the APY parallax conditions, (a) and (b) with the photo coordinates
    eliminated: ``px = sx dX + (x - x0)``, ``py = sy dY + (y - y0)``, i.e.::

        px = sx dX - c (a11 dX + a21 dY + a31 dZ) / (a13 dX + a23 dY + a33 dZ)
        py = sy dY - c (a12 dX + a22 dY + a32 dZ) / (a13 dX + a23 dY + a33 dZ)

``(px, py)`` is the shift (photo millimetres) that the optical plates must add
to the superposed image so that the photo point seen at the mark is the one
collinear with the mark's ground position. The principal point cancels in (c).

The sign of ``s``: with the conventions of :mod:`~apygis.orient.rotation` a
vertical photo with ``kappa = 0`` has ``x - x0 ~ +c dX / (Zo - Z)``, so the
superposition matches it (small parallaxes) for ``s ~ -c / (Zo - Z)``; an
optical train that turns the photo image by half a turn (the usual case, and
the one of the samples) has ``kappa ~ pi`` and ``s ~ +c / (Zo - Z) > 0``.

Scanned imagery (``scanned=True``, the seed: "Yo is set equal Y, or
Y - Yo = 0"): the projection centre travels along the ground Y axis and every
ground point is imaged from ``Yo = Y``, so ``dY = 0`` in (a), (b) and (c);
the y superposition term ``sy dY`` vanishes and ``Yo`` is not a parameter.

Examples
--------
>>> eo = ExteriorOrientation(1000.0, 2000.0, 2800.0, 0.0, 0.0, 0.0)
>>> io = InteriorOrientation(focal_mm=153.0)
>>> ground_to_photo([[1100.0, 2000.0, 500.0]], eo, io).round(6)
array([[6.652174, 0.      ]])
>>> photo_to_ground([[6.652173913, 0.0]], 500.0, eo, io).round(3)
array([[1100., 2000.,  500.]])
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from apygis.errors import DegenerateGeometryError, OrientationError
from apygis.orient._fields import finite_fields
from apygis.orient.rotation import rotation_derivatives, rotation_matrix

__all__ = [
    "EO_PARAMETERS",
    "ExteriorOrientation",
    "InteriorOrientation",
    "collinearity_jacobian",
    "depth",
    "ground_to_photo",
    "parallax",
    "parallax_jacobian",
    "photo_to_ground",
    "superposition",
]

#: Names of the six exterior orientation parameters, in the order of the Jacobians.
EO_PARAMETERS = ("Xo", "Yo", "Zo", "omega", "phi", "kappa")


@dataclass(frozen=True)
class InteriorOrientation:
    """The interior orientation of a photo.

    Parameters
    ----------
    focal_mm : float
        Principal distance ``c`` (positive, millimetres).
    x0_mm, y0_mm : float
        Principal point in photo coordinates (millimetres).
    scanned : bool
        Scanned imagery: ``Y - Yo = 0`` (see the module docstring).
    """

    focal_mm: float
    x0_mm: float = 0.0
    y0_mm: float = 0.0
    scanned: bool = False

    def __post_init__(self):
        finite_fields(self, ("focal_mm", "x0_mm", "y0_mm"), show_value=True)
        if self.focal_mm <= 0:
            raise OrientationError(f"focal_mm must be positive, got {self.focal_mm}")
        object.__setattr__(self, "scanned", bool(self.scanned))

    def to_dict(self) -> dict:
        """A JSON-ready dict (keys as the field names)."""
        return {
            "focal_mm": self.focal_mm,
            "x0_mm": self.x0_mm,
            "y0_mm": self.y0_mm,
            "scanned": self.scanned,
        }

    @classmethod
    def from_dict(cls, d) -> InteriorOrientation:
        """The inverse of :meth:`to_dict`."""
        return cls(d["focal_mm"], d.get("x0_mm", 0.0), d.get("y0_mm", 0.0), d.get("scanned", False))


@dataclass(frozen=True)
class ExteriorOrientation:
    """Projection centre and attitude of a photo.

    Parameters
    ----------
    Xo, Yo, Zo : float
        Projection centre, ground metres.
    omega_rad, phi_rad, kappa_rad : float
        Attitude, radians, conventions of :mod:`apygis.orient.rotation`.
    """

    Xo: float
    Yo: float
    Zo: float
    omega_rad: float = 0.0
    phi_rad: float = 0.0
    kappa_rad: float = 0.0
    rotation: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        names = ("Xo", "Yo", "Zo", "omega_rad", "phi_rad", "kappa_rad")
        finite_fields(self, names, show_value=True)
        R = rotation_matrix(self.omega_rad, self.phi_rad, self.kappa_rad)
        R.setflags(write=False)
        object.__setattr__(self, "rotation", R)

    @property
    def centre(self) -> np.ndarray:
        """The projection centre ``(Xo, Yo, Zo)`` as an array."""
        return np.array([self.Xo, self.Yo, self.Zo])

    @property
    def parameters(self) -> np.ndarray:
        """``(Xo, Yo, Zo, omega_rad, phi_rad, kappa_rad)`` as an array."""
        return np.array([self.Xo, self.Yo, self.Zo, self.omega_rad, self.phi_rad, self.kappa_rad])

    @classmethod
    def from_parameters(cls, p) -> ExteriorOrientation:
        """The inverse of :attr:`parameters`."""
        return cls(*(float(v) for v in p))

    def to_dict(self) -> dict:
        """A JSON-ready dict (keys as the field names)."""
        return {
            "Xo": self.Xo,
            "Yo": self.Yo,
            "Zo": self.Zo,
            "omega_rad": self.omega_rad,
            "phi_rad": self.phi_rad,
            "kappa_rad": self.kappa_rad,
        }

    @classmethod
    def from_dict(cls, d) -> ExteriorOrientation:
        """The inverse of :meth:`to_dict`."""
        return cls(d["Xo"], d["Yo"], d["Zo"], d["omega_rad"], d["phi_rad"], d["kappa_rad"])


def _points(a, n: int, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != n:
        raise OrientationError(f"{what} must have shape (N, {n}), got {a.shape}")
    return a


def _reduced(ground: np.ndarray, eo: ExteriorOrientation, scanned: bool) -> np.ndarray:
    d = ground - eo.centre
    if scanned:
        d[:, 1] = 0.0
    return d


def depth(ground, exterior: ExteriorOrientation, interior: InteriorOrientation) -> np.ndarray:
    """The z coordinate ``q_z`` of ground points in the camera frame, metres.

    ``q = R.T @ (X - Xo, Y - Yo, Z - Zo)`` (``Y - Yo = 0`` for scanned
    imagery). The camera looks down its negative z axis
    (:mod:`apygis.orient.rotation`), so a point lies **in front of** the
    camera when ``q_z < 0`` and behind it (or in the plane of the projection
    centre) otherwise; the collinearity condition (a) cannot tell the two
    apart, an orientation must.

    Examples
    --------
    >>> eo = ExteriorOrientation(0.0, 0.0, 1000.0)
    >>> depth([[0.0, 0.0, 0.0], [0.0, 0.0, 2000.0]], eo, InteriorOrientation(153.0)).tolist()
    [-1000.0, 1000.0]
    """
    g = _points(ground, 3, "ground")
    return _reduced(g, exterior, interior.scanned) @ exterior.rotation[:, 2]


def ground_to_photo(ground, exterior: ExteriorOrientation, interior: InteriorOrientation):
    """Photo coordinates of ground points by the collinearity condition (a).

    Parameters
    ----------
    ground : array_like, shape (N, 3) or (3,)
        Ground points ``(X, Y, Z)``, metres.
    exterior : ExteriorOrientation
    interior : InteriorOrientation

    Returns
    -------
    numpy.ndarray, shape (N, 2)
        Photo coordinates ``(x, y)``, millimetres. A point in the plane of
        the projection centre parallel to the image (``q_z = 0``) gives inf.
    """
    d = _reduced(_points(ground, 3, "ground"), exterior, interior.scanned)
    q = d @ exterior.rotation
    with np.errstate(divide="ignore", invalid="ignore"):
        f = -interior.focal_mm / q[:, 2]
    out = np.empty((len(q), 2))
    out[:, 0] = interior.x0_mm + f * q[:, 0]
    out[:, 1] = interior.y0_mm + f * q[:, 1]
    return out


def photo_to_ground(photo_mm, Z, exterior: ExteriorOrientation, interior: InteriorOrientation):
    """Intersect the rays of photo points with horizontal planes ``Z``.

    The ray of ``(x, y)`` has the ground direction
    ``D = R @ (x - x0, y - y0, -c)``; the point is
    ``(Xo, Yo, Zo) + (Z - Zo) / D_z * D``.

    Parameters
    ----------
    photo_mm : array_like, shape (N, 2)
        Photo coordinates, millimetres.
    Z : float or array_like, shape (N,)
        Heights of the planes, metres.
    exterior, interior :
        The photo's orientation (frame imagery only).

    Returns
    -------
    numpy.ndarray, shape (N, 3)

    Raises
    ------
    OrientationError
        For scanned imagery (with ``Y - Yo = 0`` a photo point does not
        define Y).
    DegenerateGeometryError
        If a ray is parallel to its plane or meets it behind the camera.
    """
    if interior.scanned:
        raise OrientationError(
            "photo_to_ground needs frame imagery: with scanned imagery (Y - Yo = 0) "
            "a photo point does not determine Y"
        )
    p = _points(photo_mm, 2, "photo_mm")
    Z = np.broadcast_to(np.asarray(Z, dtype=float), (len(p),))
    v = np.empty((len(p), 3))
    v[:, 0] = p[:, 0] - interior.x0_mm
    v[:, 1] = p[:, 1] - interior.y0_mm
    v[:, 2] = -interior.focal_mm
    D = v @ exterior.rotation.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (Z - exterior.Zo) / D[:, 2]
    bad = ~np.isfinite(t) | (t <= 0)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise DegenerateGeometryError(
            f"{int(bad.sum())} ray(s) (first: index {i}) are parallel to their plane Z "
            "or meet it behind the camera"
        )
    return exterior.centre + t[:, None] * D


def superposition(ground, exterior: ExteriorOrientation, interior: InteriorOrientation, sx, sy):
    """Photo coordinates that the map superposes on a ground point: (b) with zero parallax.

    ``x = x0 - sx (X - Xo)``, ``y = y0 - sy (Y - Yo)`` (``Y - Yo = 0`` for
    scanned imagery). ``sx``, ``sy`` in photo millimetres per ground metre.

    Returns
    -------
    numpy.ndarray, shape (N, 2)
    """
    d = _reduced(_points(ground, 3, "ground"), exterior, interior.scanned)
    out = np.empty((len(d), 2))
    out[:, 0] = interior.x0_mm - sx * d[:, 0]
    out[:, 1] = interior.y0_mm - sy * d[:, 1]
    return out


def parallax(ground, exterior: ExteriorOrientation, interior: InteriorOrientation, sx, sy):
    """The APY parallax conditions (c): ``px = sx dX + (x - x0)``, ``py = sy dY + (y - y0)``.

    Parameters
    ----------
    ground : array_like, shape (N, 3)
        Mark positions ``(X, Y, Z)``, metres.
    exterior, interior :
        The photo's orientation.
    sx, sy : float
        Map-to-photo scale factors, photo millimetres per ground metre.

    Returns
    -------
    numpy.ndarray, shape (N, 2)
        ``(px, py)`` in photo millimetres.

    Examples
    --------
    >>> eo = ExteriorOrientation(0.0, 0.0, 2295.0, 0.0, 0.0, np.pi)
    >>> io = InteriorOrientation(153.0)
    >>> s = 153 / 2295
    >>> parallax([[500.0, 0.0, 0.0], [500.0, 0.0, 100.0]], eo, io, s, s).round(4) + 0.0
    array([[ 0.    ,  0.    ],
           [-1.5186,  0.    ]])
    """
    g = _points(ground, 3, "ground")
    d = _reduced(g, exterior, interior.scanned)
    q = d @ exterior.rotation
    f = -interior.focal_mm / q[:, 2]
    out = np.empty((len(q), 2))
    out[:, 0] = sx * d[:, 0] + f * q[:, 0]
    out[:, 1] = sy * d[:, 1] + f * q[:, 1]
    return out


def collinearity_jacobian(ground, exterior: ExteriorOrientation, interior: InteriorOrientation):
    """Photo coordinates and their partial derivatives (collinearity (a)).

    With ``q = R.T @ d``, ``d = G - C`` (``d_y = 0`` for scanned imagery),
    ``x = x0 - c q0/q2``, ``y = y0 - c q1/q2``::

        d(x, y)/dq = -c [[1/q2, 0, -q0/q2**2], [0, 1/q2, -q1/q2**2]]
        dq/dG = R.T,  dq/dC = -R.T,  dq/dtheta = (dR/dtheta).T @ d

    Parameters
    ----------
    ground : array_like, shape (N, 3)
    exterior, interior :
        The photo's orientation.

    Returns
    -------
    photo : numpy.ndarray, shape (N, 2)
        Photo coordinates, millimetres.
    J_eo : numpy.ndarray, shape (N, 2, 6)
        Derivatives by ``(Xo, Yo, Zo, omega, phi, kappa)`` (mm per m, mm per
        rad). The ``Yo`` column is 0 for scanned imagery.
    J_ground : numpy.ndarray, shape (N, 2, 3)
        Derivatives by the ground point ``(X, Y, Z)`` (mm per m).
    """
    g = _points(ground, 3, "ground")
    d = _reduced(g, exterior, interior.scanned)
    R = exterior.rotation
    q = d @ R
    c = interior.focal_mm
    inv = 1.0 / q[:, 2]
    photo = np.empty((len(q), 2))
    photo[:, 0] = interior.x0_mm - c * q[:, 0] * inv
    photo[:, 1] = interior.y0_mm - c * q[:, 1] * inv
    Dq = np.zeros((len(q), 2, 3))
    Dq[:, 0, 0] = -c * inv
    Dq[:, 0, 2] = c * q[:, 0] * inv * inv
    Dq[:, 1, 1] = -c * inv
    Dq[:, 1, 2] = c * q[:, 1] * inv * inv
    J_ground = Dq @ R.T
    if interior.scanned:
        J_ground[:, :, 1] = 0.0
    J_eo = np.empty((len(q), 2, 6))
    J_eo[:, :, :3] = -J_ground
    dRs = rotation_derivatives(exterior.omega_rad, exterior.phi_rad, exterior.kappa_rad)
    for j, dR in enumerate(dRs):
        dq = d @ dR
        J_eo[:, :, 3 + j] = np.einsum("nij,nj->ni", Dq, dq)
    return photo, J_eo, J_ground


def parallax_jacobian(ground, exterior: ExteriorOrientation, interior: InteriorOrientation, sx, sy):
    """The parallaxes (c) and their derivatives by the eight APY parameters.

    Parameters are ``(Xo, Yo, Zo, omega, phi, kappa, sx, sy)``:
    ``dpx/dXo = -sx + dx/dXo``, ``dpy/dYo = -sy + dy/dYo``,
    ``dpx/dsx = dX``, ``dpy/dsy = dY``; the angle and ``Zo`` columns are
    those of the collinearity. For scanned imagery ``dY = 0``: the ``Yo`` and
    ``sy`` columns are 0.

    Returns
    -------
    p : numpy.ndarray, shape (N, 2)
        ``(px, py)``, millimetres.
    J : numpy.ndarray, shape (N, 2, 8)
    """
    g = _points(ground, 3, "ground")
    photo, J_eo, _ = collinearity_jacobian(g, exterior, interior)
    d = _reduced(g, exterior, interior.scanned)
    p = np.empty_like(photo)
    p[:, 0] = sx * d[:, 0] + photo[:, 0] - interior.x0_mm
    p[:, 1] = sy * d[:, 1] + photo[:, 1] - interior.y0_mm
    J = np.zeros((len(g), 2, 8))
    J[:, :, :6] = J_eo
    J[:, 0, 0] -= sx
    if not interior.scanned:
        J[:, 1, 1] -= sy
    J[:, 0, 6] = d[:, 0]
    J[:, 1, 7] = d[:, 1]
    return p, J
