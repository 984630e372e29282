"""Interior orientation: the pixel -> photo transform of a scan, found automatically.

Conventions (see :mod:`apygis.aerotri`): scan pixels ``(col, row)``, photo
coordinates ``(x, y)`` in mm (x right, y up); the transform is a
:class:`PixelTransform`. Residuals are ``v_i = T(p_i) - m_i`` (transformed
measured mark minus calibrated position), reported in micrometres.

Dihedral code ``d`` (0..7) of a scan: the scan shows the upright scan (code 0: a
film scanned the usual way, photo x along the columns, y up) turned by
``np.rot90(scan, d % 4)`` (90 degree steps counter-clockwise as displayed) and then,
for ``d >= 4``, mirrored left-right (``np.fliplr``), the convention of
:func:`apygis.aerotri.synth.dihedral`. The linear part of its transform is
``A = s R(theta) Q_d F`` with ``F = diag(1, -1)`` (rows point down), a small
rotation ``R(theta)``, a scale ``s``, and ``Q_d = R(-90 deg * (d mod 4))``,
times ``diag(-1, 1)`` on the right for ``d >= 4``.

The automatic procedure (:func:`interior_orientation`):

1. At the pyramid level whose long side is nearest 800 px, candidate marks are
   the peaks of the normalised cross-correlation with the mark design's inner
   template (:func:`apygis.aerotri.fiducials.find_candidates`).
2. For each dihedral code ``d``, a similarity with a small rotation
   (|theta| <= 10 deg) is found from every pair of candidates (among the 16
   best) and every ordered pair of calibrated fiducials; the one that brings the
   most candidates within max(2 mm, 3 coarse pixels) of a fiducial wins and is
   refitted by least squares. The codes are
   ranked by (fiducials explained, orientation mark seen at its predicted
   place, rms): the orientation mark makes a symmetric pattern's codes distinct.
3. Every calibrated fiducial is refined at level 0 by a window read around its
   predicted place (:func:`apygis.aerotri.fiducials.refine_mark`): a mark not
   found there, or not wholly inside the scan, is reported missing; fewer
   marks than a redundant fit needs raise :class:`OrientationError`.
4. The model (affine by default) is fitted by least squares to the refined
   marks; residuals per fiducial, rms and max (um); ``flagged`` when the
   largest residual exceeds ``max_residual_um``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from apygis.aerotri.camera import Camera, PixelTransform
from apygis.aerotri.fiducials import find_candidates, refine_mark
from apygis.aerotri.imagery import ImageSource
from apygis.errors import OrientationError

__all__ = [
    "MIN_POINTS",
    "InteriorResult",
    "digital_interior",
    "dihedral_code",
    "dihedral_matrix",
    "fit_transform",
    "interior_orientation",
]

#: the fewest marks that determine each model
MIN_POINTS = {"similarity": 2, "affine": 3, "projective": 4}

_F = np.array([[1.0, 0.0], [0.0, -1.0]])


def dihedral_matrix(code: int) -> np.ndarray:
    """``Q_d F`` of the module docstring: the integer 2 x 2 pixel -> photo axes of code ``d``."""
    if not 0 <= int(code) <= 7:
        raise ValueError(f"dihedral code must be 0..7, got {code}")
    k = int(code) % 4
    c, s = [1, 0, -1, 0][k], [0, -1, 0, 1][k]  # cos, sin of -90 deg * k
    q = np.array([[c, -s], [s, c]], dtype=float)
    if code >= 4:
        q = q @ np.diag([-1.0, 1.0])
    return q @ _F


def dihedral_code(transform: PixelTransform) -> int:
    """The dihedral code whose axes ``Q_d F`` are nearest the transform's linear part."""
    a = transform.matrix[:2, :2]
    return int(np.argmax([float(np.sum(a * dihedral_matrix(d))) for d in range(8)]))


# ------------------------------------------------------------------ the transform fit


def _normaliser(p: np.ndarray) -> np.ndarray:
    """A similarity ``N`` (3 x 3) taking points to mean 0 and rms distance sqrt 2."""
    c = p.mean(axis=0)
    s = math.sqrt(2.0) / max(float(np.sqrt(((p - c) ** 2).sum(axis=1).mean())), 1e-12)
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def _affine_rows(u: np.ndarray) -> np.ndarray:
    n = len(u)
    a = np.zeros((2 * n, 6))
    a[0::2, 0], a[0::2, 1], a[0::2, 2] = u[:, 0], u[:, 1], 1.0
    a[1::2, 3], a[1::2, 4], a[1::2, 5] = u[:, 0], u[:, 1], 1.0
    return a


def fit_transform(
    px, mm, model: str = "affine", *, require_redundancy: bool = False
) -> tuple[PixelTransform, np.ndarray]:
    """Least-squares pixel -> photo transform from marks ``px`` (n, 2) at ``mm`` (n, 2).

    Minimises ``sum |T(p_i) - m_i|^2`` (photo mm) over

    * ``"similarity"``: ``x = a c - b r + tx, y = b c + a r + ty`` (proper) or
      ``x = a c + b r + tx, y = b c - a r + ty`` (with a reflection, as every
      row-down scan has); both are fitted (linear) and the smaller sum wins (with
      exactly 2 points both fit exactly and the reflected one, the usual scan,
      is taken);
    * ``"affine"``: ``x = a c + b r + tx, y = d c + e r + ty`` (linear);
    * ``"projective"``: ``x = (h11 c + h12 r + h13) / (h31 c + h32 r + 1)``,
      ``y = (h21 c + h22 r + h23) / (h31 c + h32 r + 1)``: the linear DLT on
      normalised coordinates as start, then Gauss-Newton on the true residuals.

    Returns the transform and the residuals ``T(p_i) - m_i`` (n, 2, mm). Fewer
    points than the model needs (similarity 2, affine 3, projective 4) raise
    :class:`OrientationError`; so does exactly the minimum when
    ``require_redundancy`` (no redundancy: the residuals would be zero).
    """
    if model not in MIN_POINTS:
        raise OrientationError(
            f"unknown interior orientation model {model!r} (expected similarity, affine "
            "or projective)"
        )
    p = np.asarray(px, dtype=float).reshape(-1, 2)
    m = np.asarray(mm, dtype=float).reshape(-1, 2)
    if len(p) != len(m):
        raise OrientationError(f"{len(p)} pixel positions but {len(m)} photo positions")
    need = MIN_POINTS[model]
    if len(p) < need:
        raise OrientationError(f"{model} transform needs at least {need} marks, got {len(p)}")
    if require_redundancy and len(p) == need:
        raise OrientationError(
            f"{model} transform from exactly {need} marks has no redundancy "
            "(residuals would be zero, nothing checks the marks)"
        )
    # normalise both sides for conditioning: m' = Nm m, p' = Np p, T = Nm^-1 T' Np
    np_, nm = _normaliser(p), _normaliser(m)
    u = p @ np_[:2, :2].T + np_[:2, 2]
    w = m @ nm[:2, :2].T + nm[:2, 2]
    rhs = w.ravel()
    if model == "similarity":
        best = None
        for sign in (-1.0, 1.0):  # -1: reflected (a row-down scan), tried first
            a = np.zeros((2 * len(u), 4))
            a[0::2, 0], a[0::2, 1], a[0::2, 2] = u[:, 0], -sign * u[:, 1], 1.0
            a[1::2, 0], a[1::2, 1], a[1::2, 3] = sign * u[:, 1], u[:, 0], 1.0
            sol, *_ = np.linalg.lstsq(a, rhs, rcond=None)
            ssr = float(np.sum((a @ sol - rhs) ** 2))
            if best is None or ssr < best[0] - 1e-12 * max(1.0, best[0]):
                ca, cb, tx, ty = sol
                h = np.array([[ca, -sign * cb, tx], [cb, sign * ca, ty], [0.0, 0.0, 1.0]])
                best = (ssr, h)
        assert best is not None
        hn = best[1]
    elif model == "affine":
        sol, *_ = np.linalg.lstsq(_affine_rows(u), rhs, rcond=None)
        hn = np.array([sol[0:3], sol[3:6], [0.0, 0.0, 1.0]])
    else:
        hn = _projective(u, w)
    h = np.linalg.solve(nm, hn @ np_)
    try:
        t = PixelTransform(h)
    except Exception:
        raise OrientationError(
            f"{model} transform from {len(p)} marks is singular (marks collinear?)"
        ) from None
    return t, t.to_mm(p) - m


def _projective(u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Projective ``w ~ H u`` (normalised points): DLT start, Gauss-Newton on the residuals."""
    n = len(u)
    a = np.zeros((2 * n, 8))
    a[0::2, 0:2], a[0::2, 2] = u, 1.0
    a[1::2, 3:5], a[1::2, 5] = u, 1.0
    a[0::2, 6:8] = -u * w[:, 0:1]
    a[1::2, 6:8] = -u * w[:, 1:2]
    sol, *_ = np.linalg.lstsq(a, w.ravel(), rcond=None)
    h = np.append(sol, 1.0)
    for _ in range(20):
        hm = h.reshape(3, 3)
        num = u @ hm[:2, :2].T + hm[:2, 2]
        den = u @ hm[2, :2] + 1.0
        pred = num / den[:, None]
        res = (w - pred).ravel()
        jac = np.zeros((2 * n, 8))
        jac[0::2, 0:2], jac[0::2, 2] = u / den[:, None], 1.0 / den
        jac[1::2, 3:5], jac[1::2, 5] = u / den[:, None], 1.0 / den
        jac[0::2, 6:8] = -u * (pred[:, 0] / den)[:, None]
        jac[1::2, 6:8] = -u * (pred[:, 1] / den)[:, None]
        dx, *_ = np.linalg.lstsq(jac, res, rcond=None)
        h[:8] += dx
        if float(np.abs(dx).max()) < 1e-13:
            break
    return h.reshape(3, 3)


# ------------------------------------------------------------------ the result


@dataclass
class InteriorResult:
    """The interior orientation of one image (the block database stores :meth:`to_dict`).

    ``transform``: pixel -> photo mm; ``model``: similarity | affine | projective
    (``"digital"`` for a digital camera); ``dihedral``: the scan's dihedral code
    (module docstring); ``fiducials_px``: measured marks ``{name: (col, row)}``
    (level 0); ``residuals_um``: ``{name: (vx, vy)}``, ``v = T(p) - m`` in um;
    ``rms_um``: ``sqrt(mean(vx^2 + vy^2))``; ``max_um``: the largest ``|v|``;
    ``flagged``: ``max_um`` above the limit (the operator should look);
    ``missing``: calibrated fiducials not found; ``notes``: what the operator
    should know (ambiguous rotation, missing marks, ...).
    """

    transform: PixelTransform
    model: str
    dihedral: int = 0
    fiducials_px: dict[str, tuple[float, float]] = field(default_factory=dict)
    residuals_um: dict[str, tuple[float, float]] = field(default_factory=dict)
    rms_um: float = 0.0
    max_um: float = 0.0
    flagged: bool = False
    missing: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """A JSON-ready dict."""
        return {
            "transform": self.transform.to_list(),
            "model": self.model,
            "dihedral": int(self.dihedral),
            "fiducials_px": {k: [float(v[0]), float(v[1])] for k, v in self.fiducials_px.items()},
            "residuals_um": {k: [float(v[0]), float(v[1])] for k, v in self.residuals_um.items()},
            "rms_um": float(self.rms_um),
            "max_um": float(self.max_um),
            "flagged": bool(self.flagged),
            "missing": list(self.missing),
            "notes": list(self.notes),
        }

    @classmethod
    def from_dict(cls, d: dict) -> InteriorResult:
        """The inverse of :meth:`to_dict`."""
        return cls(
            transform=PixelTransform.from_list(d["transform"]),
            model=str(d["model"]),
            dihedral=int(d.get("dihedral", 0)),
            fiducials_px={k: (float(v[0]), float(v[1])) for k, v in d["fiducials_px"].items()},
            residuals_um={k: (float(v[0]), float(v[1])) for k, v in d["residuals_um"].items()},
            rms_um=float(d["rms_um"]),
            max_um=float(d["max_um"]),
            flagged=bool(d["flagged"]),
            missing=[str(v) for v in d.get("missing", [])],
            notes=[str(v) for v in d.get("notes", [])],
        )


def digital_interior(camera: Camera, width: int, height: int) -> InteriorResult:
    """The fixed interior orientation of a digital camera's ``width x height`` image."""
    if camera.kind != "digital" or camera.pixel_um is None or camera.sensor_px is None:
        raise OrientationError(
            f"camera {camera.name!r} is not a digital camera (it needs interior_orientation)"
        )
    if (int(width), int(height)) != tuple(camera.sensor_px):
        raise OrientationError(
            f"camera {camera.name!r}: image is {width} x {height} px but the sensor is "
            f"{camera.sensor_px[0]} x {camera.sensor_px[1]} px"
        )
    return InteriorResult(transform=camera.pixel_transform(), model="digital", dihedral=0)


# ------------------------------------------------------------------ the automatic procedure

#: the order in which equally good dihedral codes are preferred (nearest the identity first)
_IDENTITY_ORDER = (0, 1, 3, 2, 4, 5, 7, 6)


#: hypotheses are made from pairs among this many best candidates (all are counted)
_PAIR_CANDIDATES = 16


def _pick_level(source: ImageSource, target: int = 800) -> int:
    sizes = [max(source.shape(k)) for k in range(source.levels)]
    return int(np.argmin([abs(math.log(s / target)) for s in sizes]))


def _similarity_search(
    q: np.ndarray, fid: np.ndarray, scale_range: tuple[float, float], tol_mm: float
) -> tuple[int, np.ndarray | None]:
    """Best small-rotation similarity ``mm = z q + t`` (complex) by pair hypotheses.

    ``q``: candidates (complex, dihedral axes applied, coarse pixels); ``fid``:
    calibrated fiducials (complex, mm). Returns (fiducials explained, (z, t)).
    """
    n, m = len(q), len(fid)
    if n < 2 or m < 2:
        return 0, None
    i, j = np.triu_indices(min(n, _PAIR_CANDIDATES), 1)  # the best-scoring ones pair up
    a, b = np.nonzero(~np.eye(m, dtype=bool))
    dq = (q[j] - q[i])[:, None]
    dm = (fid[b] - fid[a])[None, :]
    z = dm / dq
    ok = (np.abs(np.angle(z)) <= math.radians(10.0)) & (np.abs(z) >= scale_range[0])
    ok &= np.abs(z) <= scale_range[1]
    ok &= np.abs(dm) >= 20.0
    pi, pa = np.nonzero(ok)
    if len(pi) == 0:
        return 0, None
    zz = z[pi, pa]
    tt = fid[a[pa]] - zz * q[i[pi]]
    pred = zz[:, None] * q[None, :] + tt[:, None]  # (h, n)
    dist = np.abs(pred[:, :, None] - fid[None, None, :])  # (h, n, m)
    hit = dist.min(axis=1) <= tol_mm  # fiducials explained
    count = hit.sum(axis=1)
    resid = np.where(hit, dist.min(axis=1), 0.0).sum(axis=1)
    best = int(np.lexsort((resid, -count))[0])
    return int(count[best]), np.array([zz[best], tt[best]])


def _refit(q, fid, zt, tol_mm):
    """Assign candidates to fiducials under ``zt`` and refit the similarity (complex LSQ)."""
    z, t = zt
    pairs: list[tuple[int, int]] = []
    for _ in range(3):
        pred = z * q + t
        dist = np.abs(pred[:, None] - fid[None, :])
        pairs = []
        for k in range(len(fid)):
            i = int(np.argmin(dist[:, k]))
            if dist[i, k] <= tol_mm and int(np.argmin(dist[i, :])) == k:
                pairs.append((i, k))
        if len(pairs) < 2:
            break
        qi = np.array([q[i] for i, _ in pairs])
        fk = np.array([fid[k] for _, k in pairs])
        a = np.column_stack([qi, np.ones_like(qi)])
        sol, *_ = np.linalg.lstsq(a, fk, rcond=None)
        z, t = sol
    pred = z * q + t
    rms = (
        float(np.sqrt(np.mean([abs(pred[i] - fid[k]) ** 2 for i, k in pairs])))
        if pairs
        else math.inf
    )
    return np.array([z, t]), pairs, rms


def interior_orientation(
    source: ImageSource,
    camera: Camera,
    *,
    model: str = "affine",
    max_residual_um: float = 10.0,
    approx_pixel_um: float | None = None,
    name: str | None = None,
) -> InteriorResult:
    """Automatic interior orientation of a scanned film photo (module docstring).

    ``source``: the scan (an :class:`ImageSource`; level 0 is read only in small
    windows around the marks). ``approx_pixel_um``: the scan's pixel size, if
    known; otherwise it is taken as ``240 mm / long side`` (a scan of the
    230 mm frame with a margin) and the search allows 0.85..1.5 times that
    (templates at 1, 1.15 and 1.3 times).
    ``name`` names the image in errors and notes. Raises
    :class:`OrientationError` when the marks found cannot determine ``model``
    with redundancy.
    """
    where = name if name is not None else str(getattr(source, "name", "image"))
    if camera.kind != "film" or not camera.fiducials:
        raise OrientationError(f"{where}: camera {camera.name!r} has no fiducials")
    if model not in MIN_POINTS:
        raise OrientationError(
            f"{where}: unknown interior orientation model {model!r} (expected similarity, "
            "affine or projective)"
        )
    if approx_pixel_um is not None and not (
        math.isfinite(approx_pixel_um) and 0.1 <= approx_pixel_um <= 1000.0
    ):
        raise OrientationError(f"{where}: approx_pixel_um {approx_pixel_um} is not in 0.1..1000 um")
    names = list(camera.fiducials)
    fid_mm = camera.fiducial_array
    fid = fid_mm[:, 0] + 1j * fid_mm[:, 1]
    h0, w0 = source.shape(0)
    pix0_mm = (approx_pixel_um / 1000.0) if approx_pixel_um else 240.0 / max(h0, w0)
    level = _pick_level(source)
    hl, wl = source.shape(level)
    pix_mm = pix0_mm * 2.0**level
    coarse = source.read(level, 0, 0, wl, hl)
    # without a pixel size: the scan covers the frame's marks (>= ~225 mm, so pixels
    # of at least 0.93 x nominal) and usually a margin (up to ~1.5 x nominal)
    scales = (1.0,) if approx_pixel_um else (1.0, 1.15, 1.3)
    xy, _ = find_candidates(coarse, pix_mm, scales=scales)
    if len(xy) < 2:
        raise OrientationError(
            f"{where}: found {len(xy)} fiducial mark candidate(s) at pyramid level {level}; "
            f"camera {camera.name!r} has {len(names)}"
        )
    omark = camera.orientation_mark_mm
    oxy, _ = (
        find_candidates(coarse, pix_mm, orientation=True, threshold=0.6, scales=scales)
        if omark is not None
        else (np.zeros((0, 2)), np.zeros(0))
    )
    spread = (0.9, 1.1) if approx_pixel_um else (0.85, 1.5)
    scale_range = (pix_mm * spread[0], pix_mm * spread[1])
    tol = max(2.0, 3.0 * pix_mm)
    ranked = []
    for d in range(8):
        qd = xy @ dihedral_matrix(d).T
        q = qd[:, 0] + 1j * qd[:, 1]
        count, zt = _similarity_search(q, fid, scale_range, tol)
        if zt is None or count < 2:
            continue
        zt, pairs, rms = _refit(q, fid, zt, tol)
        seen = False
        if omark is not None and len(oxy):
            oq = oxy @ dihedral_matrix(d).T
            opred = zt[0] * (oq[:, 0] + 1j * oq[:, 1]) + zt[1]
            seen = bool(np.any(np.abs(opred - complex(*omark)) <= tol))
        ranked.append((len(pairs), seen, rms, d, zt))
    if not ranked:
        raise OrientationError(
            f"{where}: {len(xy)} mark candidate(s) found but no similarity maps two of "
            f"them onto the calibrated fiducials of camera {camera.name!r}"
        )
    best_count = max(r[0] for r in ranked)
    best_seen = max(r[1] for r in ranked if r[0] == best_count)
    tops = [r for r in ranked if r[0] == best_count and r[1] == best_seen]
    best_rms = min(r[2] for r in tops)
    ties = [r for r in tops if r[2] <= 2.0 * best_rms + 0.5 * pix_mm]
    ties.sort(key=lambda r: _IDENTITY_ORDER.index(r[3]))
    _, _, _, code, zt = ties[0]
    notes: list[str] = []
    if len(ties) > 1:
        why = (
            "the camera has no orientation mark"
            if omark is None
            else "the orientation mark was not found"
        )
        notes.append(
            f"rotation ambiguous: {why} and the fiducial pattern fits dihedral codes "
            f"{sorted(r[3] for r in ties)} equally; code {code} (nearest the identity) taken"
        )
    elif omark is not None and not best_seen:
        notes.append("orientation mark not found; the rotation rests on the fiducials")
    # coarse similarity (coarse pixels -> mm) as a 2 x 3 matrix, then at level 0
    z, t = zt
    qm = dihedral_matrix(code)
    zm = np.array([[z.real, -z.imag], [z.imag, z.real]])
    lin_l = zm @ qm
    f = 2.0**level
    lin0 = lin_l / f  # c_l = (c_0 - (f - 1)/2) / f
    off0 = np.array([t.real, t.imag]) - lin0 @ np.full(2, (f - 1.0) / 2.0)
    pred0 = np.linalg.solve(lin0, (fid_mm - off0).T).T
    search = max(1.0, 4.0 * pix_mm)
    found: dict[str, tuple[float, float]] = {}
    missing: list[str] = []
    # a mark counts only with its whole disk and ring (1.6 mm) inside the scan: the
    # edge padding of a window would bias a cut mark
    reach = 1.6 / float(np.sqrt(abs(np.linalg.det(lin0))))

    def inside(xy) -> bool:
        c, r = xy
        return reach <= c <= w0 - 1 - reach and reach <= r <= h0 - 1 - reach

    for nm_, p in zip(names, pred0, strict=True):
        fit = refine_mark(source, p, lin0, search_mm=search) if inside(p) else None
        if fit is not None and fit.ok and inside(fit.xy):
            found[nm_] = fit.xy
        else:
            missing.append(nm_)
    need = MIN_POINTS[model]
    if len(found) <= need:
        raise OrientationError(
            f"{where}: found {len(found)} of {len(names)} fiducial marks "
            f"({', '.join(found) or 'none'}; missing {', '.join(missing) or 'none'}); "
            f"the {model} transform needs more than {need} to be checked"
        )
    if missing:
        notes.append(f"fiducial(s) {', '.join(missing)} not found")
    keys = list(found)
    px = np.array([found[k] for k in keys])
    mm = np.array([camera.fiducials[k] for k in keys], dtype=float)
    transform, res = fit_transform(px, mm, model, require_redundancy=True)
    res_um = res * 1000.0
    norm = np.hypot(res_um[:, 0], res_um[:, 1])
    rms = float(np.sqrt(np.mean(norm**2)))
    mx = float(norm.max())
    flagged = mx > max_residual_um
    if flagged:
        worst = keys[int(np.argmax(norm))]
        notes.append(
            f"largest residual {mx:.1f} um at fiducial {worst} exceeds {max_residual_um:g} um"
        )
    return InteriorResult(
        transform=transform,
        model=model,
        dihedral=dihedral_code(transform),
        fiducials_px={k: (float(v[0]), float(v[1])) for k, v in zip(keys, px, strict=True)},
        residuals_um={k: (float(v[0]), float(v[1])) for k, v in zip(keys, res_um, strict=True)},
        rms_um=rms,
        max_um=mx,
        flagged=flagged,
        missing=missing,
        notes=notes,
    )
