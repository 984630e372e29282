"""Omega-phi-kappa rotation matrices: THE photogrammetric conventions of apygis.

Every module of :mod:`apygis.orient` follows the conventions stated here and
refers to this docstring instead of restating them.

Coordinate systems
------------------
Ground (object) space
    A right-handed system X (east), Y (north), Z (up), in metres; in Switzerland
    LV95 east/north and heights above sea level.
Image space
    A right-handed system x, y, z fixed to the photo, in millimetres. The
    photo coordinates x, y lie in the image plane; the origin of the system is
    the projection centre, the camera looks down the **negative z axis** and
    the (positive) image lies in the plane ``z = -c``. The principal point has
    the photo coordinates ``(x0, y0)``.
Principal distance
    ``c`` (``focal_mm``) is positive, in millimetres. An image point is the
    vector ``(x - x0, y - y0, -c)`` in image space.

Rotation matrix
---------------
The rotation matrix ``R`` turns image-space vectors into ground-space
directions::

    R = R_omega(X) @ R_phi(Y) @ R_kappa(Z)

    R_omega = [[1, 0, 0], [0, cos w, -sin w], [0, sin w, cos w]]
    R_phi   = [[cos p, 0, sin p], [0, 1, 0], [-sin p, 0, cos p]]
    R_kappa = [[cos k, -sin k, 0], [sin k, cos k, 0], [0, 0, 1]]

that is: first kappa about the z axis, then phi about the y axis, then omega
about the X axis (omega is the primary rotation, kappa the tertiary one). Each
elementary rotation is right-handed: a positive angle turns counter-clockwise
when seen from the positive end of its axis looking towards the origin.
Angles are in radians (``omega_rad``, ``phi_rad``, ``kappa_rad``).

Written out (``cw = cos omega``, ``sw = sin omega``, and so on)::

    a11 =  cp ck                 a12 = -cp sk                 a13 =  sp
    a21 =  cw sk + sw sp ck      a22 =  cw ck - sw sp sk      a23 = -sw cp
    a31 =  sw sk - cw sp ck      a32 =  sw ck + cw sp sk      a33 =  cw cp

The element ``a_ij = R[i-1, j-1]`` is the ``a_ij`` of the APY collinearity
conditions (a) of the seed::

    x - x0 = -c (a11 dX + a21 dY + a31 dZ) / (a13 dX + a23 dY + a33 dZ)
    y - y0 = -c (a12 dX + a22 dY + a32 dZ) / (a13 dX + a23 dY + a33 dZ)

with ``dX = X - Xo``, ``dY = Y - Yo``, ``dZ = Z - Zo`` and ``(Xo, Yo, Zo)`` the
projection centre; in matrix form ``(x - x0, y - y0, -c) = -c q / q_z`` with
``q = R.T @ (X - Xo, Y - Yo, Z - Zo)``. For a vertical photo (all angles 0)
the ground point below and east of the centre appears at positive x: the photo
is a positive, with the same orientation as the map. A photo turned by half a
turn on its stage has ``kappa = pi``.

The inverse :func:`angles_from_matrix` returns ``omega`` and ``kappa`` in
``(-pi, pi]`` and ``phi`` in ``[-pi/2, pi/2]``.

Examples
--------
>>> import numpy as np
>>> R = rotation_matrix(0.01, -0.02, 3.0)
>>> np.allclose(R @ R.T, np.eye(3))
True
>>> [round(float(a), 12) for a in angles_from_matrix(R)]
[0.01, -0.02, 3.0]
"""

from __future__ import annotations

import numpy as np

from apygis.errors import DegenerateGeometryError

__all__ = [
    "angles_from_matrix",
    "nearest_rotation",
    "rotation_derivatives",
    "rotation_matrix",
]


def rotation_matrix(omega_rad, phi_rad, kappa_rad) -> np.ndarray:
    """The rotation matrix ``R = R_omega @ R_phi @ R_kappa`` (see the module docstring).

    Parameters
    ----------
    omega_rad, phi_rad, kappa_rad : float or array_like
        The angles in radians; arrays broadcast against each other.

    Returns
    -------
    numpy.ndarray
        Shape ``(..., 3, 3)``: one matrix per broadcast angle triple,
        ``(3, 3)`` for scalars. ``R[..., i-1, j-1]`` is the seed's ``a_ij``.

    Examples
    --------
    >>> rotation_matrix(0.0, 0.0, np.pi / 2).round(12) + 0.0
    array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    >>> rotation_matrix([0.0, 0.1], 0.0, 0.0).shape
    (2, 3, 3)
    """
    w, p, k = np.broadcast_arrays(
        np.asarray(omega_rad, dtype=float),
        np.asarray(phi_rad, dtype=float),
        np.asarray(kappa_rad, dtype=float),
    )
    cw, sw = np.cos(w), np.sin(w)
    cp, sp = np.cos(p), np.sin(p)
    ck, sk = np.cos(k), np.sin(k)
    R = np.empty((*w.shape, 3, 3))
    R[..., 0, 0] = cp * ck
    R[..., 0, 1] = -cp * sk
    R[..., 0, 2] = sp
    R[..., 1, 0] = cw * sk + sw * sp * ck
    R[..., 1, 1] = cw * ck - sw * sp * sk
    R[..., 1, 2] = -sw * cp
    R[..., 2, 0] = sw * sk - cw * sp * ck
    R[..., 2, 1] = sw * ck + cw * sp * sk
    R[..., 2, 2] = cw * cp
    return R


def rotation_derivatives(
    omega_rad, phi_rad, kappa_rad
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Analytic partial derivatives ``dR/domega, dR/dphi, dR/dkappa``.

    With ``R = R_omega R_phi R_kappa``::

        dR/domega = R_omega' R_phi  R_kappa
        dR/dphi   = R_omega  R_phi' R_kappa
        dR/dkappa = R_omega  R_phi  R_kappa'

    where ``'`` is the derivative of the elementary rotation by its angle.

    Parameters
    ----------
    omega_rad, phi_rad, kappa_rad : float or array_like
        The angles in radians (broadcast).

    Returns
    -------
    tuple of numpy.ndarray
        Three arrays of shape ``(..., 3, 3)``, per radian.

    Examples
    --------
    >>> dw, dp, dk = rotation_derivatives(0.1, 0.2, 0.3)
    >>> h = 1e-7
    >>> num = (rotation_matrix(0.1, 0.2, 0.3 + h) - rotation_matrix(0.1, 0.2, 0.3 - h)) / (2 * h)
    >>> bool(np.allclose(dk, num, atol=1e-8))
    True
    """
    w, p, k = np.broadcast_arrays(
        np.asarray(omega_rad, dtype=float),
        np.asarray(phi_rad, dtype=float),
        np.asarray(kappa_rad, dtype=float),
    )
    cw, sw = np.cos(w), np.sin(w)
    cp, sp = np.cos(p), np.sin(p)
    ck, sk = np.cos(k), np.sin(k)
    z = np.zeros_like(w)
    o = np.ones_like(w)

    def mat(*rows):
        return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)

    Rw = mat((o, z, z), (z, cw, -sw), (z, sw, cw))
    Rp = mat((cp, z, sp), (z, o, z), (-sp, z, cp))
    Rk = mat((ck, -sk, z), (sk, ck, z), (z, z, o))
    dRw = mat((z, z, z), (z, -sw, -cw), (z, cw, -sw))
    dRp = mat((-sp, z, cp), (z, z, z), (-cp, z, -sp))
    dRk = mat((-sk, -ck, z), (ck, -sk, z), (z, z, z))
    return dRw @ Rp @ Rk, Rw @ dRp @ Rk, Rw @ Rp @ dRk


def angles_from_matrix(R) -> tuple:
    """The angles ``(omega_rad, phi_rad, kappa_rad)`` of a rotation matrix.

    Inverse of :func:`rotation_matrix`: ``phi = asin(a13)``,
    ``omega = atan2(-a23, a33)``, ``kappa = atan2(-a12, a11)``.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices (orthonormal, determinant +1).

    Returns
    -------
    tuple
        ``(omega_rad, phi_rad, kappa_rad)``, floats for one matrix or arrays of
        shape ``(...)``; omega and kappa in ``(-pi, pi]``, phi in
        ``[-pi/2, pi/2]``.

    Raises
    ------
    DegenerateGeometryError
        If a matrix is not a rotation (not orthonormal or a reflection), or
        if cos(phi) < 1e-9 (phi at +-pi/2, gimbal lock: omega and kappa are
        then not separable).
    """
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise DegenerateGeometryError(f"a rotation matrix must be 3 x 3, got shape {R.shape}")
    eye = np.eye(3)
    ortho = np.abs(np.swapaxes(R, -1, -2) @ R - eye).max(axis=(-2, -1))
    det = np.linalg.det(R)
    if np.any(ortho > 1e-6) or np.any(det < 0):
        raise DegenerateGeometryError(
            "not a rotation matrix (not orthonormal, or a reflection with determinant -1)"
        )
    a13 = np.clip(R[..., 0, 2], -1.0, 1.0)
    if np.any(np.hypot(R[..., 0, 0], R[..., 0, 1]) < 1e-9):
        raise DegenerateGeometryError(
            "phi is +-pi/2 (gimbal lock): omega and kappa are not separable"
        )
    phi = np.arcsin(a13)
    omega = np.arctan2(-R[..., 1, 2], R[..., 2, 2])
    kappa = np.arctan2(-R[..., 0, 1], R[..., 0, 0])
    if phi.ndim == 0:
        return float(omega), float(phi), float(kappa)
    return omega, phi, kappa


def nearest_rotation(M) -> np.ndarray:
    """The rotation matrix nearest (Frobenius norm) to a 3 x 3 matrix.

    ``U @ diag(1, 1, det(U V^T)) @ V^T`` from the singular value decomposition
    ``M = U S V^T``; used to clean up matrices from closed-form solutions.

    Parameters
    ----------
    M : array_like, shape (3, 3)

    Returns
    -------
    numpy.ndarray, shape (3, 3)

    Examples
    --------
    >>> Q = nearest_rotation(2.0 * rotation_matrix(0.1, 0.2, 0.3))
    >>> bool(np.allclose(Q, rotation_matrix(0.1, 0.2, 0.3)))
    True
    """
    M = np.asarray(M, dtype=float)
    if M.shape != (3, 3) or not np.all(np.isfinite(M)):
        raise DegenerateGeometryError("nearest_rotation needs a finite 3 x 3 matrix")
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    return U @ np.diag([1.0, 1.0, d]) @ Vt
