"""Feature-based matching (FBM) of Förstner points between the images of a pair.

The "block formation" of PHODIS AT (seed, section 3.1): on an intermediate
pyramid level, interest points of two images are matched by their grey values
and the outliers are removed by a robust geometric model, relative orientation
for a pair in a strip and a projective/affine transform for a cross-strip
pair with little overlap.

Area matching without descriptors
    A prediction ``H`` (3 x 3 homography, pixels of image a -> pixels of image
    b, both at the matching level) brings b into a's frame, so that patches are
    compared under the right rotation and scale (strips flown in alternating
    directions differ by half a turn, rotated scans by a quarter). The patch of
    a point ``p_a`` of a is ``g_a(p_a + d)`` and the patch of a point ``p_b`` of
    b is ``g_b(H (H^-1 p_b + d))`` for the ``patch x patch`` offsets ``d``
    (bilinear interpolation), i.e. b resampled on a's grid around the predicted
    position ``H^-1 p_b``. Candidates of ``p_a`` are the points of b with
    ``|H^-1 p_b - p_a| <= search_px``; the score is the normalised cross
    correlation::

        ncc = sum (g_a - mean g_a)(g_b - mean g_b) / sqrt(sum (g_a - mean)^2 sum (g_b - mean)^2)

    A pair is accepted when its ``ncc >= ncc_min``, it beats a's second-best
    candidate by ``margin`` (distinctness) and a is also b's best candidate
    (mutual consistency).

Robust model, strip pair (``kind="strip"`` with the photo transforms)
    The matched pixels go to photo millimetres ``(x, y)`` and to normalised
    camera rays ``u = (x - x0, y - y0, -c) / (-c) = (-(x - x0)/c, -(y - y0)/c, 1)``
    (the camera looks down its ``-z`` axis, :mod:`apygis.orient.rotation`;
    ``x0 = y0 = 0`` here: a principal point of a few micrometres changes
    nothing at this level). The coplanarity condition of the relative
    orientation is the epipolar constraint ``u_b^T E u_a = 0`` with the
    essential matrix ``E = [t]_x R`` (rotation ``R`` and base direction ``t``
    of b relative to a). RANSAC (5-point, ``cv2.findEssentialMat``) with the
    threshold ``threshold_px`` (pixels of the level, converted to normalised
    units by ``pixel_mm / c``) gives the inliers; then ``(R, t)`` (five
    parameters) is refined by least squares on the inliers' Sampson distances::

        e = u_b^T E u_a / sqrt((E u_a)_1^2 + (E u_a)_2^2 + (E^T u_b)_1^2 + (E^T u_b)_2^2)

    (to first order the smallest root-sum-square correction of the four image
    coordinates that satisfies the constraint, so for image coordinates of
    standard deviation ``sigma`` each, ``e`` has standard deviation ``sigma``:
    the same residual as :mod:`apygis.orient.relative`), with rejection at
    ``3 sigma`` (three rounds). ``sigma_px`` is the RMS of ``e`` of the inliers,
    in pixels of the level.

Robust model, cross-strip pair (``kind="cross"`` or no photo transforms)
    RANSAC homography (``cv2.findHomography``, threshold ``2 threshold_px``:
    relief departs from one plane), then a least-squares homography on the
    inliers with ``3 sigma`` rejection (three rounds), then the affine check:
    over a's image the homography's projective denominator must stay within
    ``[0.8, 1.25]``, it must keep the sense of rotation of the photos (in
    pixels: no mirror, unless one of the two scans is mirrored against the
    other, as their photo transforms tell) and scale by ``0.25 .. 4``.
    ``sigma_px`` is the RMS per coordinate of the transfer residuals
    ``H p_a - p_b`` of the inliers divided by ``sqrt 2`` (both points are
    measured).

Unknown or poor prediction
    With ``predict=None`` or fewer than ``min_inliers`` inliers, the prediction
    is estimated from the images themselves: SIFT keypoints
    (``cv2.SIFT_create``), Lowe's ratio test (0.8) and a RANSAC homography;
    the area matcher then runs once more with it, so that the final matches are
    always between the Förstner points (what the tracks are built on).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage, optimize
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from apygis.aerotri.camera import PixelTransform
from apygis.aerotri.interest import InterestPoints
from apygis.errors import OrientationError
from apygis.orient.collinearity import ExteriorOrientation

__all__ = ["PairMatches", "homography_from_orientations", "match_pair"]

PhotoMap = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True, eq=False)
class PairMatches:
    """Matches of one image pair (see the module docstring).

    Attributes
    ----------
    idx_a, idx_b : numpy.ndarray of int
        Indices of the matched points into ``pts_a`` / ``pts_b``.
    xy_a, xy_b : numpy.ndarray, shape (n, 2)
        Their pixel positions at the matching level.
    ncc : numpy.ndarray
        Normalised cross correlation of each match.
    homography : numpy.ndarray (3 x 3) or None
        Least-squares homography a-px -> b-px of the inliers (a prediction for
        the next lower level, after scaling).
    essential : numpy.ndarray (3 x 3) or None
        Essential matrix ``E`` with ``u_b^T E u_a = 0`` (strip pairs).
    sigma_px : float
        RMS residual of the inliers, pixels of the level (module docstring).
    n_candidates : int
        Pairs that passed the NCC, distinctness and mutuality tests.
    n_inliers : int
        Matches kept by the robust model (= ``len(idx_a)``).
    reason : str
        Why the pair failed ("" when it did not).
    predicted_by : str
        ``"given"``, ``"sift"`` or ``""`` (no usable prediction).
    """

    idx_a: np.ndarray
    idx_b: np.ndarray
    xy_a: np.ndarray
    xy_b: np.ndarray
    ncc: np.ndarray
    homography: np.ndarray | None
    essential: np.ndarray | None
    sigma_px: float
    n_candidates: int
    n_inliers: int
    reason: str = ""
    predicted_by: str = ""

    def __len__(self) -> int:
        return len(self.idx_a)


def _empty(reason: str, n_candidates: int = 0, predicted_by: str = "") -> PairMatches:
    z = np.empty(0, dtype=np.intp)
    return PairMatches(
        z, z.copy(), np.empty((0, 2)), np.empty((0, 2)), np.empty(0), None, None,
        math.nan, n_candidates, 0, reason, predicted_by,
    )  # fmt: skip


def _apply_h(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    h = p @ H[:2, :2].T + H[:2, 2]
    w = p @ H[2, :2] + H[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h / w[:, None]


# --------------------------------------------------------------------- prediction


def _as_matrix(t) -> np.ndarray:
    if isinstance(t, PixelTransform):
        return np.asarray(t.matrix, dtype=float)
    m = np.asarray(t, dtype=float)
    if m.shape != (3, 3):
        raise OrientationError(
            f"a pixel transform must be a PixelTransform or 3 x 3, got {m.shape}"
        )
    return m


def _level_matrix(level: int) -> np.ndarray:
    f = 2.0**level
    return np.array([[f, 0.0, (f - 1) / 2], [0.0, f, (f - 1) / 2], [0.0, 0.0, 1.0]])


def _plane_to_photo(eo: ExteriorOrientation, focal_mm: float, pp, Z: float) -> np.ndarray:
    """3 x 3 map ``(X, Y, 1)`` of the plane ``Z`` -> homogeneous photo ``(x, y, 1)`` (mm)."""
    A = np.array([[1.0, 0.0, -eo.Xo], [0.0, 1.0, -eo.Yo], [0.0, 0.0, Z - eo.Zo]])
    K = np.array([[-focal_mm, 0.0, pp[0]], [0.0, -focal_mm, pp[1]], [0.0, 0.0, 1.0]])
    return K @ eo.rotation.T @ A


def homography_from_orientations(
    eo_a: ExteriorOrientation,
    eo_b: ExteriorOrientation,
    focal_mm: float,
    pixel_a: PixelTransform | np.ndarray,
    pixel_b: PixelTransform | np.ndarray,
    terrain_z: float,
    *,
    level: int = 0,
    principal_point_mm: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """The homography pixels of a -> pixels of b through the ground plane ``Z = terrain_z``.

    With ``q = R^T (X - Xo, Y - Yo, Z - Zo)`` the collinearity condition
    (:mod:`apygis.orient.collinearity`) reads ``x - x0 = -c q_x / q_z``,
    ``y - y0 = -c q_y / q_z``; on the plane ``Z = Z_t`` this is the
    homography ``G = K R^T A`` of ``(X, Y, 1)`` with
    ``A = [[1, 0, -Xo], [0, 1, -Yo], [0, 0, Z_t - Zo]]`` and
    ``K = [[-c, 0, x0], [0, -c, y0], [0, 0, 1]]``. Pixels ``p`` of a level
    ``k`` are photo millimetres ``T L_k p`` (``T`` the level-0
    :class:`PixelTransform`, ``L_k`` the level -> level-0 map of
    :func:`apygis.aerotri.imagery.level_to_full`), so::

        H = (T_b L_k)^-1 G_b G_a^-1 (T_a L_k)

    Parameters
    ----------
    eo_a, eo_b : ExteriorOrientation
        Approximate orientations (frame photos looking down).
    focal_mm : float
        Principal distance ``c``.
    pixel_a, pixel_b : PixelTransform or 3 x 3 array
        Level-0 pixel -> photo transforms of the two images.
    terrain_z : float
        Mean terrain height, metres.
    level : int
        Pyramid level of the pixel coordinates that ``H`` maps.
    """
    L = _level_matrix(level)
    Ta = _as_matrix(pixel_a) @ L
    Tb = _as_matrix(pixel_b) @ L
    Ga = _plane_to_photo(eo_a, focal_mm, principal_point_mm, terrain_z)
    Gb = _plane_to_photo(eo_b, focal_mm, principal_point_mm, terrain_z)
    H = np.linalg.solve(Tb, Gb @ np.linalg.solve(Ga, Ta))
    return H / H[2, 2]


def _sift_prediction(
    img_a: np.ndarray, img_b: np.ndarray, mirrored: bool = False
) -> np.ndarray | None:
    """A homography a-px -> b-px from SIFT features (ratio test 0.8, RANSAC), or None.

    SIFT's descriptors do not survive a mirror: when the scans are mirrored against each
    other (``mirrored``), b is matched flipped left to right and the flip composed back.
    """
    if mirrored:
        w = np.shape(img_b)[1]
        flip = np.array([[-1.0, 0.0, w - 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        H = _sift_prediction(img_a, np.asarray(img_b)[:, ::-1])
        return None if H is None else flip @ H

    def u8(img):
        a = np.asarray(img, dtype=np.float32)
        lo, hi = np.percentile(a, [0.5, 99.5])
        return np.clip((a - lo) * (255.0 / max(hi - lo, 1e-6)), 0, 255).astype(np.uint8)

    sift = cv2.SIFT_create(nfeatures=4000)  # type: ignore[attr-defined]
    ka, da = sift.detectAndCompute(u8(img_a), None)
    kb, db = sift.detectAndCompute(u8(img_b), None)
    if da is None or db is None or len(ka) < 8 or len(kb) < 8:
        return None
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(da, db, k=2)
    good = [m[0] for m in knn if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
    if len(good) < 12:
        return None
    pa = np.array([ka[m.queryIdx].pt for m in good], dtype=np.float32)
    pb = np.array([kb[m.trainIdx].pt for m in good], dtype=np.float32)
    H, mask = cv2.findHomography(pa, pb, cv2.RANSAC, 6.0, maxIters=3000, confidence=0.999)
    if H is None or mask is None or int(mask.sum()) < 12:
        return None
    return np.asarray(H, dtype=float)


# --------------------------------------------------------------------- area matching


def _patches(img: np.ndarray, grid_xy: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``img`` at ``grid_xy`` (n x m x 2, col/row); NaN outside."""
    n, m, _ = grid_xy.shape
    coords = np.stack([grid_xy[..., 1].ravel(), grid_xy[..., 0].ravel()])
    h, w = img.shape
    out = ndimage.map_coordinates(img, coords, order=1, mode="nearest")
    inside = (
        (coords[0] >= -0.5) & (coords[0] <= h - 0.5) & (coords[1] >= -0.5) & (coords[1] <= w - 0.5)
    )
    out = np.where(inside, out, np.nan)
    return out.reshape(n, m).astype(np.float32)


def _normalise(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Zero-mean unit-norm rows and a validity mask (finite, not flat)."""
    ok = np.isfinite(p).all(axis=1)
    q = np.where(ok[:, None], p, 0.0)
    q = q - q.mean(axis=1, keepdims=True)
    nrm = np.sqrt((q * q).sum(axis=1))
    ok &= nrm > 1e-3 * math.sqrt(p.shape[1])
    q = q / np.where(ok, nrm, 1.0)[:, None]
    return q.astype(np.float32), ok


def _best_two(key: np.ndarray, score: np.ndarray, n: int):
    """Per key value: index (into the pair arrays) of the best score and the second score."""
    order = np.lexsort((-score, key))
    k = key[order]
    first = np.ones(len(k), dtype=bool)
    first[1:] = k[1:] != k[:-1]
    best = np.full(n, -1, dtype=np.intp)
    best[k[first]] = order[first]
    second = np.full(n, -np.inf)
    sec = np.zeros(len(k), dtype=bool)
    sec[1:] = first[:-1] & ~first[1:]
    second[k[sec]] = score[order[sec]]
    return best, second


def _area_match(img_a, img_b, xa, xb, H, search_px, patch, ncc_min, margin):
    """Candidate matches (ia, ib, ncc) by NCC, distinctness and mutuality."""
    r = patch // 2
    d = np.arange(-r, r + 1, dtype=float)
    dy, dx = np.meshgrid(d, d, indexing="ij")
    offs = np.column_stack([dx.ravel(), dy.ravel()])  # (m, 2)
    pb_a = _apply_h(np.linalg.inv(H), xb)  # b's points in a's frame
    Pa, ok_a = _normalise(_patches(img_a, xa[:, None, :] + offs[None]))
    grid_b = (pb_a[:, None, :] + offs[None]).reshape(-1, 2)
    Pb, ok_b = _normalise(_patches(img_b, _apply_h(H, grid_b).reshape(len(xb), -1, 2)))
    ok_b &= np.isfinite(pb_a).all(axis=1)
    ia_ok = np.flatnonzero(ok_a)
    ib_ok = np.flatnonzero(ok_b)
    if len(ia_ok) == 0 or len(ib_ok) == 0:
        return np.empty(0, np.intp), np.empty(0, np.intp), np.empty(0)
    ta = cKDTree(xa[ia_ok])
    tb = cKDTree(pb_a[ib_ok])
    sdm = ta.sparse_distance_matrix(tb, search_px, output_type="ndarray")
    i = ia_ok[sdm["i"]]
    j = ib_ok[sdm["j"]]
    if len(i) == 0:
        return np.empty(0, np.intp), np.empty(0, np.intp), np.empty(0)
    ncc = np.empty(len(i), dtype=np.float32)
    step = 50_000
    for s in range(0, len(i), step):
        ncc[s : s + step] = np.einsum("ij,ij->i", Pa[i[s : s + step]], Pb[j[s : s + step]])
    best_a, second_a = _best_two(i, ncc, len(xa))
    best_b, _ = _best_two(j, ncc, len(xb))
    cand = best_a[best_a >= 0]
    keep = (
        (ncc[cand] >= ncc_min)
        & (ncc[cand] - second_a[i[cand]] >= margin)
        & (best_b[j[cand]] == cand)  # mutual: b's best is the same pair
    )
    cand = cand[keep]
    return i[cand], j[cand], ncc[cand].astype(float)


# --------------------------------------------------------------------- robust models


def _skew(t):
    return np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])


def _sampson(E, ua, ub):
    Ea = ua @ E.T
    Etb = ub @ E
    num = np.einsum("ij,ij->i", ub, Ea)
    den = np.sqrt(Ea[:, 0] ** 2 + Ea[:, 1] ** 2 + Etb[:, 0] ** 2 + Etb[:, 1] ** 2)
    return num / np.where(den > 0, den, 1e-300)


def refine_essential(R0, t0, ua, ub):
    """Least-squares ``(R, t)`` (5 parameters) minimising the Sampson distances."""
    t0 = t0 / np.linalg.norm(t0)
    e1 = np.cross(t0, [1.0, 0.0, 0.0] if abs(t0[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(t0, e1)

    def model(x):
        R = Rotation.from_rotvec(x[:3]).as_matrix() @ R0
        t = t0 + x[3] * e1 + x[4] * e2
        return _skew(t / np.linalg.norm(t)) @ R

    sol = optimize.least_squares(lambda x: _sampson(model(x), ua, ub), np.zeros(5), method="lm")
    return model(sol.x)


def _strip_model(xy_a, xy_b, photo_a, photo_b, focal_mm, threshold_px):
    """Inlier mask, essential matrix and sigma (px) of the relative orientation."""
    ma = np.asarray(photo_a(xy_a), dtype=float)
    mb = np.asarray(photo_b(xy_b), dtype=float)
    ua = np.column_stack([-ma / focal_mm, np.ones(len(ma))])
    ub = np.column_stack([-mb / focal_mm, np.ones(len(mb))])
    p0 = np.asarray(photo_a(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])), dtype=float)
    u, v = p0[1] - p0[0], p0[2] - p0[0]
    pix_mm = math.sqrt(abs(u[0] * v[1] - u[1] * v[0]))  # sqrt of the pixel's area
    unit = pix_mm / focal_mm  # one pixel in normalised units
    E, mask = cv2.findEssentialMat(
        ua[:, :2], ub[:, :2], np.eye(3), method=cv2.RANSAC, prob=0.999,
        threshold=threshold_px * unit, maxIters=3000,
    )  # fmt: skip
    if E is None or mask is None or E.shape[0] < 3:
        return None
    E = E[:3]
    inl = mask.ravel() > 0
    if inl.sum() < 8:
        return None
    _, R, t, _ = cv2.recoverPose(E, ua[inl, :2], ub[inl, :2], np.eye(3))
    R0, t0 = np.asarray(R, dtype=float), np.asarray(t, dtype=float).ravel()
    for _ in range(3):
        E = refine_essential(R0, t0, ua[inl], ub[inl])
        e = _sampson(E, ua, ub) / unit
        sigma = math.sqrt(float(np.mean(e[inl] ** 2)))
        new = np.abs(e) <= max(3.0 * sigma, 0.25)
        if np.array_equal(new, inl) or new.sum() < 8:
            break
        inl = new
        # the rotation/base of this round start the next one
        _, R, t, _ = cv2.recoverPose(E, ua[inl, :2], ub[inl, :2], np.eye(3))
        R0, t0 = np.asarray(R, dtype=float), np.asarray(t, dtype=float).ravel()
    e = _sampson(E, ua, ub) / unit
    sigma = math.sqrt(float(np.mean(e[inl] ** 2)))
    return inl, E / np.linalg.norm(E), sigma


def _plausible(H, shape_a, mirrored: bool = False) -> bool:
    """The affine check of a cross-strip homography (module docstring); ``mirrored``: the
    scans are mirrored against each other (the pixel homography turns the other way)."""
    h, w = shape_a
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=float)
    den = corners @ H[2, :2] + H[2, 2]
    A = H[:2, :2] / H[2, 2] - np.outer(H[:2, 2], H[2, :2]) / H[2, 2] ** 2
    det = float(np.linalg.det(A)) * (-1.0 if mirrored else 1.0)
    return bool(np.all((den > 0.8) & (den < 1.25)) and 0.25**2 < det < 4.0**2)


def _mirrored(photo_a: PhotoMap | None, photo_b: PhotoMap | None) -> bool:
    """Whether the pixel -> photo maps of a and b turn opposite ways (one scan mirrored
    against the other); False when either is unknown."""
    if photo_a is None or photo_b is None:
        return False
    probe = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    signs = []
    for photo in (photo_a, photo_b):
        q = np.asarray(photo(probe), dtype=float)
        u, v = q[1] - q[0], q[2] - q[0]
        signs.append(np.sign(u[0] * v[1] - u[1] * v[0]))
    return bool(signs[0] * signs[1] < 0)


def _homography_model(xy_a, xy_b, threshold_px, shape_a, mirrored: bool = False):
    """Inlier mask, homography and sigma (px per coordinate) of a cross-strip pair."""
    H, mask = cv2.findHomography(
        xy_a.astype(np.float32), xy_b.astype(np.float32), cv2.RANSAC, 2.0 * threshold_px,
        maxIters=3000, confidence=0.999,
    )  # fmt: skip
    if H is None or mask is None:
        return None
    inl = mask.ravel() > 0
    for _ in range(3):
        if inl.sum() < 8:
            return None
        H, _ = cv2.findHomography(xy_a[inl], xy_b[inl], 0)
        if H is None:
            return None
        res = np.linalg.norm(_apply_h(H, xy_a) - xy_b, axis=1)
        sigma = math.sqrt(float(np.mean(res[inl] ** 2)) / 2.0)
        new = res <= max(3.0 * sigma * math.sqrt(2.0), 0.5)
        if np.array_equal(new, inl):
            break
        inl = new
    if inl.sum() < 8 or not _plausible(H, shape_a, mirrored):
        return None
    res = np.linalg.norm(_apply_h(H, xy_a) - xy_b, axis=1)
    return inl, np.asarray(H, dtype=float), math.sqrt(float(np.mean(res[inl] ** 2)) / 2.0)


# --------------------------------------------------------------------- the pair


def _match_once(
    img_a, img_b, pts_a, pts_b, H, search_px, kind, photo_a, photo_b, focal_mm,
    patch, ncc_min, margin, threshold_px, predicted_by,
) -> PairMatches:  # fmt: skip
    xa = np.asarray(pts_a.xy, dtype=float).reshape(-1, 2)
    xb = np.asarray(pts_b.xy, dtype=float).reshape(-1, 2)
    ia, ib, ncc = _area_match(img_a, img_b, xa, xb, H, search_px, patch, ncc_min, margin)
    n_cand = len(ia)
    if n_cand < 8:
        return _empty(f"only {n_cand} candidate matches", n_cand, predicted_by)
    strip = kind == "strip" and photo_a is not None and photo_b is not None and focal_mm
    essential = None
    if strip:
        out = _strip_model(xa[ia], xb[ib], photo_a, photo_b, float(focal_mm), threshold_px)
        if out is None:
            return _empty("relative orientation failed (RANSAC)", n_cand, predicted_by)
        inl, essential, sigma = out
    else:
        out2 = _homography_model(
            xa[ia], xb[ib], threshold_px, np.shape(img_a), _mirrored(photo_a, photo_b)
        )
        if out2 is None:
            return _empty("no plausible homography (RANSAC)", n_cand, predicted_by)
        inl, _, sigma = out2
    ia, ib, ncc = ia[inl], ib[inl], ncc[inl]
    Hf, _ = cv2.findHomography(xa[ia], xb[ib], 0) if len(ia) >= 4 else (None, None)
    return PairMatches(
        idx_a=ia, idx_b=ib, xy_a=xa[ia], xy_b=xb[ib], ncc=ncc,
        homography=None if Hf is None else np.asarray(Hf, dtype=float) / Hf[2, 2],
        essential=essential, sigma_px=float(sigma), n_candidates=n_cand, n_inliers=len(ia),
        reason="", predicted_by=predicted_by,
    )  # fmt: skip


def match_pair(
    img_a,
    img_b,
    pts_a: InterestPoints,
    pts_b: InterestPoints,
    *,
    predict: np.ndarray | None = None,
    search_px: float = 40.0,
    kind: str = "strip",
    photo_a: PhotoMap | None = None,
    photo_b: PhotoMap | None = None,
    focal_mm: float | None = None,
    patch: int = 11,
    ncc_min: float = 0.7,
    margin: float = 0.05,
    threshold_px: float = 1.5,
    min_inliers: int = 30,
) -> PairMatches:
    """Match the Förstner points of two images of one pyramid level (module docstring).

    Parameters
    ----------
    img_a, img_b : 2-D arrays
        The two images at the matching level (grey values).
    pts_a, pts_b : InterestPoints
        Their Förstner points (pixel coordinates of that level).
    predict : 3 x 3 array, optional
        Homography a-px -> b-px from the approximate orientations
        (:func:`homography_from_orientations`); None: estimated by SIFT.
    search_px : float
        Radius around the predicted position, pixels of a.
    kind : "strip" or "cross"
        Robust model: relative orientation (needs ``photo_a``, ``photo_b``
        and ``focal_mm``) or homography.
    photo_a, photo_b : callable, optional
        Pixel (n x 2, this level) -> photo millimetres (n x 2).
    focal_mm : float, optional
        Principal distance ``c``.
    patch : int
        Side of the correlation window, pixels (odd).
    ncc_min, margin : float
        Least correlation and least lead over the second-best candidate.
    threshold_px : float
        RANSAC threshold, pixels of the level (homography: twice this).
    min_inliers : int
        Fewer inliers with a given prediction: retry with the SIFT prediction.
    """
    if kind not in ("strip", "cross"):
        raise ValueError(f"kind must be 'strip' or 'cross', got {kind!r}")
    if patch < 3 or patch % 2 == 0:
        raise ValueError(f"patch must be an odd number >= 3, got {patch}")
    a = np.asarray(img_a, dtype=np.float32)
    b = np.asarray(img_b, dtype=np.float32)
    if len(pts_a) < 8 or len(pts_b) < 8:
        return _empty(f"too few interest points ({len(pts_a)}, {len(pts_b)})")
    args = (search_px, kind, photo_a, photo_b, focal_mm, patch, ncc_min, margin, threshold_px)
    result = None
    if predict is not None:
        H = np.asarray(predict, dtype=float).reshape(3, 3)
        result = _match_once(a, b, pts_a, pts_b, H, *args, "given")
        if result.n_inliers >= min_inliers:
            return result
    Hs = _sift_prediction(a, b, _mirrored(photo_a, photo_b))
    if Hs is None:
        return (
            result
            if result is not None and result.n_inliers
            else _empty("no prediction: SIFT found no consistent homography", 0, "")
        )
    second = _match_once(a, b, pts_a, pts_b, Hs, *args, "sift")
    if result is not None and result.n_inliers >= second.n_inliers:
        return result
    return second
