"""Tie points scored against the truth of a synthetic block.

A tie point is a set of image measurements of one ground point. Its true
ground point is where the ray of its **reference** measurement meets the
true DEM (:meth:`apygis.aerotri.synth.Truth.ground`); the truth for each of its
other measurements is that ground point projected into the other image
(:meth:`~apygis.aerotri.synth.Truth.project`). The error of a measurement is
``measured - true`` in full-resolution pixels; reference measurements have no
error by construction and are not scored. Every method (apygis's LSM,
COLMAP's SIFT) is scored the same way.

Figures: RMS and median of the error length ``|e|``; the 95th percentile;
gross errors (``|e| > 1 px``) in percent; the "core" RMS over measurements
with ``|e| <= 1 px``; and, where the method gives a precision, the ratio of
the normalised errors ``e / sigma`` (per coordinate) over the core
measurements: 1 when the sigmas are right, below 1 when they are pessimistic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TieScore", "score_block", "score_tracks"]

GROSS_PX = 1.0


@dataclass
class TieScore:
    """Figures of :func:`score_tracks` (pixels unless named otherwise)."""

    measurements: int
    points: int
    rms_px: float
    median_px: float
    p95_px: float
    gross_pct: float
    core_rms_px: float
    sigma_ratio: float | None
    errors: np.ndarray

    def to_dict(self) -> dict:
        return {
            "measurements": self.measurements,
            "points": self.points,
            "rms_px": round(self.rms_px, 4),
            "median_px": round(self.median_px, 4),
            "p95_px": round(self.p95_px, 4),
            "gross_pct": round(self.gross_pct, 3),
            "core_rms_px": round(self.core_rms_px, 4),
            "sigma_ratio": None if self.sigma_ratio is None else round(self.sigma_ratio, 3),
        }


def score_tracks(truth, tracks, *, visible_only: bool = True) -> TieScore:
    """Score tracks: a list of ``(ref_image, ref_xy, [(image, xy, sigma_or_None), ...])``."""
    errs: list[np.ndarray] = []
    sig: list[float] = []
    err_with_sigma: list[np.ndarray] = []
    by_ref: dict[int, list[int]] = {}
    for k, (ref, _, _) in enumerate(tracks):
        by_ref.setdefault(int(ref), []).append(k)
    points = 0
    for ref, ks in by_ref.items():
        ref_xy = np.array([tracks[k][1] for k in ks], dtype=float)
        ground = truth.ground(ref, ref_xy)
        points += len(ks)
        per_image: dict[int, list[tuple[int, np.ndarray, float | None]]] = {}
        for j, k in enumerate(ks):
            for img, xy, s in tracks[k][2]:
                per_image.setdefault(int(img), []).append((j, np.asarray(xy, float), s))
        for img, items in per_image.items():
            js = np.array([j for j, _, _ in items])
            meas = np.array([xy for _, xy, _ in items])
            true = truth.project(img, ground[js])
            e = meas - true
            errs.append(e)
            for (_, _, s), ee in zip(items, e, strict=True):
                if s is not None and np.isfinite(s):
                    sig.append(float(s))
                    err_with_sigma.append(ee)
    if not errs:
        nan = float("nan")
        return TieScore(0, points, nan, nan, nan, nan, nan, None, np.empty((0, 2)))
    E = np.concatenate(errs)
    d = np.hypot(E[:, 0], E[:, 1])
    core = d <= GROSS_PX
    ratio = None
    if sig:
        S = np.asarray(sig)
        Es = np.asarray(err_with_sigma)
        ds = np.hypot(Es[:, 0], Es[:, 1])
        c = ds <= GROSS_PX
        if c.sum() > 10:  # RMS of the normalised errors e / sigma, per coordinate
            ratio = float(np.sqrt(np.mean((Es[c] / S[c, None]) ** 2)))
    return TieScore(
        measurements=len(d),
        points=points,
        rms_px=float(np.sqrt(np.mean(d**2))),
        median_px=float(np.median(d)),
        p95_px=float(np.percentile(d, 95)),
        gross_pct=float(100.0 * np.mean(~core)),
        core_rms_px=float(np.sqrt(np.mean(d[core] ** 2))) if core.any() else float("nan"),
        sigma_ratio=ratio,
        errors=E,
    )


def score_block(block, truth) -> TieScore:
    """Score the tie points of a block (its ``lsm-ref`` observation is the reference)."""
    rows = block.conn.execute(
        "SELECT o.point, o.image, o.x_px, o.y_px, o.sigma_px, o.source FROM observations o "
        "JOIN points p ON p.id = o.point WHERE p.kind = 'tie' ORDER BY o.point"
    ).fetchall()
    pts: dict[int, dict] = {}
    for pid, img, x, y, s, src in rows:
        d = pts.setdefault(pid, {"ref": None, "others": []})
        if src == "lsm-ref":
            d["ref"] = (img, (x, y))
        else:
            d["others"].append((img, (x, y), s))
    tracks = [(d["ref"][0], d["ref"][1], d["others"]) for d in pts.values() if d["ref"] is not None]
    return score_tracks(truth, tracks)
