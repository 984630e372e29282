"""The block project: one SQLite database per block (schema in ``docs/aerotri.md``).

A block holds cameras, images (paths, approximate projection centres, flight
directions, strips), subblocks, interior orientations, points (tie, new and
control) with their image observations and precisions, the planned pairs
(models) with their matching results, von Gruber gap counts, per-task progress
(so that an interrupted run continues where it stopped) and the history of
runs. The database is opened in WAL mode; every writer commits whole units of
work (one image's pyramid, one pair's matches, one track group), so a killed
run leaves the block consistent.

Image files stay where they are: paths are stored relative to the block's
folder where possible (and absolute otherwise), so a block moved with its
images keeps working. Pyramids go to the folder ``<block>.pyramids`` beside it.

Versioning: ``meta.schema_version``. Opening a block of an older schema
migrates it in place (``MIGRATIONS``, each step in one transaction); a block of
a newer schema is refused with the version numbers.
"""

from __future__ import annotations

import json
import os
import sqlite3
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from apygis.aerotri.camera import Camera
from apygis.errors import ApygisError, FileOverwriteError

__all__ = ["SCHEMA_VERSION", "Block", "BlockError", "ImageRecord"]

SCHEMA_VERSION = 3


class BlockError(ApygisError, ValueError):
    """A block database that cannot be used as asked (names the block and why)."""


SCHEMA_V1 = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE cameras (
    id INTEGER PRIMARY KEY, name TEXT NOT NULL, spec TEXT NOT NULL);
CREATE TABLE images (
    image INTEGER PRIMARY KEY, strip INTEGER, camera INTEGER NOT NULL REFERENCES cameras(id),
    path TEXT NOT NULL, width INTEGER NOT NULL, height INTEGER NOT NULL,
    X REAL, Y REAL, Z REAL, heading_deg REAL, position_source TEXT NOT NULL DEFAULT '',
    exif_time TEXT);
CREATE TABLE strips (strip INTEGER PRIMARY KEY, kind TEXT NOT NULL, direction_deg REAL);
CREATE TABLE subblocks (subblock INTEGER NOT NULL, strip INTEGER NOT NULL,
    PRIMARY KEY (subblock, strip));
CREATE TABLE interior (
    image INTEGER PRIMARY KEY REFERENCES images(image), model TEXT NOT NULL,
    transform TEXT NOT NULL, rms_um REAL, max_um REAL, flagged INTEGER NOT NULL DEFAULT 0,
    result TEXT NOT NULL);
CREATE TABLE pairs (
    a INTEGER NOT NULL, b INTEGER NOT NULL, kind TEXT NOT NULL, overlap REAL,
    status TEXT NOT NULL DEFAULT 'planned', n_matches INTEGER, sigma_px REAL,
    reason TEXT NOT NULL DEFAULT '', PRIMARY KEY (a, b));
CREATE TABLE features (
    image INTEGER NOT NULL, level INTEGER NOT NULL, xy BLOB NOT NULL,
    PRIMARY KEY (image, level));
CREATE TABLE pair_matches (
    a INTEGER NOT NULL, b INTEGER NOT NULL, idx_a BLOB NOT NULL, idx_b BLOB NOT NULL,
    PRIMARY KEY (a, b));
CREATE TABLE points (
    id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, kind TEXT NOT NULL,
    X REAL, Y REAL, Z REAL, sigma_xy_m REAL, sigma_z_m REAL, ref_image INTEGER);
CREATE TABLE observations (
    point INTEGER NOT NULL REFERENCES points(id) ON DELETE CASCADE,
    image INTEGER NOT NULL REFERENCES images(image),
    x_px REAL NOT NULL, y_px REAL NOT NULL, x_mm REAL, y_mm REAL,
    sigma_px REAL, corr REAL, source TEXT NOT NULL, PRIMARY KEY (point, image));
CREATE INDEX observations_image ON observations(image);
CREATE TABLE gaps (
    a INTEGER NOT NULL, b INTEGER NOT NULL, region INTEGER NOT NULL, count INTEGER NOT NULL,
    PRIMARY KEY (a, b, region));
CREATE TABLE tasks (
    kind TEXT NOT NULL, key TEXT NOT NULL, status TEXT NOT NULL, finished TEXT,
    PRIMARY KEY (kind, key));
CREATE TABLE runs (
    id INTEGER PRIMARY KEY, command TEXT NOT NULL, args TEXT NOT NULL, started TEXT NOT NULL,
    finished TEXT, status TEXT NOT NULL, summary TEXT);
"""

#: Migrations: ``version -> SQL`` that brings a block of that version to the next.
MIGRATIONS: dict[int, str] = {
    # 2: the azimuth of each image's photo x axis, found by matching when a camera is
    # yawed against the flight (drones); NULL: along the flight
    1: "ALTER TABLE images ADD COLUMN x_azimuth_deg REAL;",
    # 3: the bundle adjustment's results (apygis at adjust): each run, the exterior
    # orientations, the adjusted points and every observation's residual and verdict
    2: """
CREATE TABLE adjustments (
    id INTEGER PRIMARY KEY, started TEXT NOT NULL, finished TEXT, options TEXT NOT NULL,
    report TEXT);
CREATE TABLE exterior (
    image INTEGER PRIMARY KEY REFERENCES images(image), adjustment INTEGER NOT NULL,
    X REAL NOT NULL, Y REAL NOT NULL, Z REAL NOT NULL,
    omega REAL NOT NULL, phi REAL NOT NULL, kappa REAL NOT NULL,
    sX REAL, sY REAL, sZ REAL, somega REAL, sphi REAL, skappa REAL);
CREATE TABLE adjusted_points (
    point INTEGER PRIMARY KEY REFERENCES points(id) ON DELETE CASCADE,
    adjustment INTEGER NOT NULL, X REAL NOT NULL, Y REAL NOT NULL, Z REAL NOT NULL,
    sX REAL, sY REAL, sZ REAL, rXY REAL, rays INTEGER NOT NULL);
CREATE TABLE residuals (
    point INTEGER NOT NULL, image INTEGER NOT NULL, adjustment INTEGER NOT NULL,
    vx_px REAL, vy_px REAL, w REAL, rejected INTEGER NOT NULL DEFAULT 0,
    reason TEXT NOT NULL DEFAULT '', PRIMARY KEY (point, image),
    FOREIGN KEY (point, image) REFERENCES observations(point, image) ON DELETE CASCADE);
""",
}

POINT_KINDS = ("tie", "new", "full", "planimetric", "height", "check")


@dataclass(frozen=True)
class ImageRecord:
    """One image of a block (paths absolute, as resolved from the block's folder)."""

    image: int
    strip: int | None
    camera: int
    path: Path
    width: int
    height: int
    X: float | None
    Y: float | None
    Z: float | None
    heading_deg: float | None
    position_source: str
    x_azimuth_deg: float | None = None


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


class Block:
    """An open block database (a context manager; see the module docstring)."""

    def __init__(self, path: Path, conn: sqlite3.Connection):
        self.path = path
        self.conn = conn

    # -- opening ---------------------------------------------------------------------------
    @classmethod
    def create(cls, path, *, crs: str = "", overwrite: bool = False) -> Block:
        """A new, empty block at ``path`` (refuses an existing file unless ``overwrite``)."""
        path = Path(path)
        if path.exists() or path.is_symlink():
            if not overwrite:
                raise FileOverwriteError(
                    f"{path}: the block exists (use --overwrite to replace it)"
                )
            if not path.is_file():
                raise BlockError(f"{path}: exists and is not a block file")
            for p in (path, Path(f"{path}-wal"), Path(f"{path}-shm")):
                p.unlink(missing_ok=True)
        path.parent.mkdir(parents=True, exist_ok=True)
        conn = cls._connect(path)
        with conn:
            conn.executescript(SCHEMA_V1)
            for version in range(1, SCHEMA_VERSION):
                conn.executescript(MIGRATIONS[version])
            conn.executemany(
                "INSERT INTO meta VALUES (?, ?)",
                [
                    ("schema_version", str(SCHEMA_VERSION)),
                    ("crs", crs),
                    ("created", _now()),
                    ("tie_name_start", "1000000"),
                    ("tie_name_interval", "1"),
                    ("tie_name_next", "1000000"),
                ],
            )
        return cls(path, conn)

    @classmethod
    def open(cls, path) -> Block:
        """Open an existing block, migrating an older schema in place."""
        path = Path(path)
        if not path.is_file():
            raise BlockError(f"{path}: no such block (create it with 'apygis at init')")
        with open(path, "rb") as f:
            if f.read(16) != b"SQLite format 3\x00":
                raise BlockError(f"{path}: not a block database (not SQLite)")
        conn = cls._connect(path)
        try:
            row = conn.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
        except sqlite3.DatabaseError as exc:
            conn.close()
            raise BlockError(f"{path}: not a block database ({exc})") from None
        if row is None or not str(row[0]).isdigit():
            conn.close()
            raise BlockError(f"{path}: not a block database (no schema version)")
        version = int(row[0])
        if version > SCHEMA_VERSION:
            conn.close()
            raise BlockError(
                f"{path}: block schema {version} was written by a newer apygis "
                f"(this one reads up to {SCHEMA_VERSION})"
            )
        while version < SCHEMA_VERSION:
            with conn:
                conn.executescript(MIGRATIONS[version])
                version += 1
                conn.execute(
                    "UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(version),)
                )
        return cls(path, conn)

    @staticmethod
    def _connect(path: Path) -> sqlite3.Connection:
        try:
            conn = sqlite3.connect(path, timeout=60.0)
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA foreign_keys=ON")
            conn.execute("PRAGMA synchronous=NORMAL")
        except sqlite3.DatabaseError as exc:
            raise BlockError(f"{path}: cannot open the block database ({exc})") from None
        return conn

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> Block:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- meta ------------------------------------------------------------------------------
    def meta(self, key: str, default: str | None = None) -> str | None:
        row = self.conn.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return row[0] if row else default

    def set_meta(self, key: str, value) -> None:
        with self.conn:
            self.conn.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, str(value)))

    @property
    def crs(self) -> str:
        return self.meta("crs", "") or ""

    @property
    def pyramid_folder(self) -> Path:
        return self.path.with_name(self.path.name + ".pyramids")

    # -- cameras and images ----------------------------------------------------------------
    def add_camera(self, camera: Camera) -> int:
        with self.conn:
            cur = self.conn.execute(
                "INSERT INTO cameras (name, spec) VALUES (?, ?)",
                (camera.name, json.dumps(camera.to_dict())),
            )
        return int(cur.lastrowid or 0)

    def cameras(self) -> dict[int, Camera]:
        rows = self.conn.execute("SELECT id, spec FROM cameras ORDER BY id").fetchall()
        return {i: Camera.from_dict(json.loads(s), f"{self.path}: camera {i}") for i, s in rows}

    def _stored_path(self, p: Path) -> str:
        p = Path(os.path.abspath(p))
        try:
            return os.path.relpath(p, os.path.abspath(self.path.parent))
        except ValueError:  # another drive
            return str(p)

    def add_images(self, rows: Iterable[dict]) -> None:
        """Insert images: dicts with image, strip, camera, path, width, height, X, Y, Z,
        heading_deg, position_source, exif_time."""
        with self.conn:
            for r in rows:
                self.conn.execute(
                    "INSERT INTO images (image, strip, camera, path, width, height, X, Y, Z, "
                    "heading_deg, position_source, exif_time) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                    (
                        r["image"], r.get("strip"), r["camera"], self._stored_path(r["path"]),
                        r["width"], r["height"], r.get("X"), r.get("Y"), r.get("Z"),
                        r.get("heading_deg"), r.get("position_source", ""), r.get("exif_time"),
                    ),
                )  # fmt: skip

    def images(self) -> list[ImageRecord]:
        rows = self.conn.execute(
            "SELECT image, strip, camera, path, width, height, X, Y, Z, heading_deg, "
            "position_source, x_azimuth_deg FROM images ORDER BY image"
        ).fetchall()
        base = self.path.parent
        return [
            ImageRecord(
                r[0], r[1], r[2], base / r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10], r[11]
            )
            for r in rows
        ]  # fmt: skip

    def update_images(self, values: dict[int, dict]) -> None:
        """Set columns (strip, heading_deg, X, Y, Z) of images: ``{image: {column: value}}``."""
        allowed = {"strip", "heading_deg", "X", "Y", "Z", "position_source", "x_azimuth_deg"}
        with self.conn:
            for image, cols in values.items():
                for k, v in cols.items():
                    if k not in allowed:
                        raise KeyError(k)
                    self.conn.execute(f"UPDATE images SET {k} = ? WHERE image = ?", (v, image))

    def set_strips(self, strips: dict[int, tuple[str, float | None]]) -> None:
        with self.conn:
            self.conn.execute("DELETE FROM strips")
            self.conn.executemany(
                "INSERT INTO strips VALUES (?, ?, ?)", [(s, k, d) for s, (k, d) in strips.items()]
            )

    def strips(self) -> dict[int, tuple[str, float | None]]:
        rows = self.conn.execute("SELECT strip, kind, direction_deg FROM strips").fetchall()
        return {s: (k, d) for s, k, d in rows}

    def set_subblocks(self, subblocks: Sequence[Sequence[int]]) -> None:
        with self.conn:
            self.conn.execute("DELETE FROM subblocks")
            self.conn.executemany(
                "INSERT INTO subblocks VALUES (?, ?)",
                [(i, s) for i, strips in enumerate(subblocks, 1) for s in strips],
            )

    def subblocks(self) -> list[list[int]]:
        out: dict[int, list[int]] = {}
        for sb, s in self.conn.execute("SELECT subblock, strip FROM subblocks ORDER BY 1, 2"):
            out.setdefault(sb, []).append(s)
        return [out[k] for k in sorted(out)]

    # -- interior orientation --------------------------------------------------------------
    def set_interior(self, image: int, result: dict) -> None:
        with self.conn:
            self.conn.execute(
                "INSERT OR REPLACE INTO interior VALUES (?, ?, ?, ?, ?, ?, ?)",
                (
                    image, result["model"], json.dumps(result["transform"]),
                    result.get("rms_um"), result.get("max_um"), int(bool(result.get("flagged"))),
                    json.dumps(result),
                ),
            )  # fmt: skip

    def interior(self) -> dict[int, dict]:
        rows = self.conn.execute("SELECT image, result FROM interior").fetchall()
        return {i: json.loads(r) for i, r in rows}

    # -- control and points ----------------------------------------------------------------
    def add_points(self, rows: Iterable[dict]) -> dict[str, int]:
        """Insert points (dicts: name, kind, X, Y, Z, sigma_xy_m, sigma_z_m, ref_image);
        returns ``{name: id}``. A name used before is refused."""
        ids: dict[str, int] = {}
        with self.conn:
            for r in rows:
                if r["kind"] not in POINT_KINDS:
                    raise BlockError(
                        f"{self.path}: point kind {r['kind']!r} is not one of {POINT_KINDS}"
                    )
                try:
                    cur = self.conn.execute(
                        "INSERT INTO points (name, kind, X, Y, Z, sigma_xy_m, sigma_z_m, "
                        "ref_image) VALUES (?,?,?,?,?,?,?,?)",
                        (r["name"], r["kind"], r.get("X"), r.get("Y"), r.get("Z"),
                         r.get("sigma_xy_m"), r.get("sigma_z_m"), r.get("ref_image")),
                    )  # fmt: skip
                except sqlite3.IntegrityError:
                    raise BlockError(f"{self.path}: point name {r['name']!r} is taken") from None
                ids[r["name"]] = int(cur.lastrowid or 0)
        return ids

    def control(self) -> list[dict]:
        rows = self.conn.execute(
            "SELECT name, kind, X, Y, Z, sigma_xy_m, sigma_z_m FROM points "
            "WHERE kind IN ('full', 'planimetric', 'height', 'check') ORDER BY name"
        ).fetchall()
        keys = ("name", "kind", "X", "Y", "Z", "sigma_xy_m", "sigma_z_m")
        return [dict(zip(keys, r, strict=True)) for r in rows]

    def tie_names(self, n: int) -> list[str]:
        """``n`` new tie point names from the start value and interval (never issued twice)."""
        start = int(self.meta("tie_name_start") or 1000000)
        step = int(self.meta("tie_name_interval") or 1)
        nxt = max(int(self.meta("tie_name_next") or start), start)
        names = [str(nxt + i * step) for i in range(n)]
        self.set_meta("tie_name_next", nxt + n * step)
        return names

    # -- pairs, features, matches, tasks ---------------------------------------------------
    def set_pairs(self, pairs: Iterable[tuple[int, int, str, float]]) -> None:
        """The planned pairs (a, b, kind, overlap); keeps the results of pairs still planned."""
        with self.conn:
            new = {(a, b): (k, o) for a, b, k, o in pairs}
            old = {(a, b) for a, b in self.conn.execute("SELECT a, b FROM pairs")}
            for a, b in old - set(new):
                self.conn.execute("DELETE FROM pairs WHERE a = ? AND b = ?", (a, b))
            for (a, b), (k, o) in new.items():
                self.conn.execute(
                    "INSERT INTO pairs (a, b, kind, overlap) VALUES (?, ?, ?, ?) "
                    "ON CONFLICT (a, b) DO UPDATE SET kind = excluded.kind, "
                    "overlap = excluded.overlap",
                    (a, b, k, o),
                )

    def pairs(self) -> list[dict]:
        rows = self.conn.execute(
            "SELECT a, b, kind, overlap, status, n_matches, sigma_px, reason FROM pairs "
            "ORDER BY a, b"
        ).fetchall()
        keys = ("a", "b", "kind", "overlap", "status", "n_matches", "sigma_px", "reason")
        return [dict(zip(keys, r, strict=True)) for r in rows]

    def set_features(self, image: int, level: int, xy: np.ndarray) -> None:
        with self.conn:
            self.conn.execute(
                "INSERT OR REPLACE INTO features VALUES (?, ?, ?)",
                (image, level, np.ascontiguousarray(xy, dtype="<f4").tobytes()),
            )

    def features(self, image: int, level: int) -> np.ndarray | None:
        row = self.conn.execute(
            "SELECT xy FROM features WHERE image = ? AND level = ?", (image, level)
        ).fetchone()
        return (
            None if row is None else np.frombuffer(row[0], dtype="<f4").reshape(-1, 2).astype(float)
        )

    def set_pair_matches(
        self, a: int, b: int, idx_a, idx_b, status: str, sigma_px, reason: str
    ) -> None:
        with self.conn:
            self.conn.execute(
                "INSERT OR REPLACE INTO pair_matches VALUES (?, ?, ?, ?)",
                (a, b, np.asarray(idx_a, "<i4").tobytes(), np.asarray(idx_b, "<i4").tobytes()),
            )
            self.conn.execute(
                "UPDATE pairs SET status = ?, n_matches = ?, sigma_px = ?, reason = ? "
                "WHERE a = ? AND b = ?",
                (status, len(idx_a), sigma_px, reason, a, b),
            )

    def pair_matches(self) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        rows = self.conn.execute("SELECT a, b, idx_a, idx_b FROM pair_matches ORDER BY a, b")
        return [
            (a, b, np.frombuffer(ia, "<i4").astype(int), np.frombuffer(ib, "<i4").astype(int))
            for a, b, ia, ib in rows
        ]

    def task_done(self, kind: str, key: str) -> bool:
        row = self.conn.execute(
            "SELECT status FROM tasks WHERE kind = ? AND key = ?", (kind, key)
        ).fetchone()
        return bool(row and row[0] == "done")

    def mark_task(self, kind: str, key: str, status: str = "done") -> None:
        with self.conn:
            self.conn.execute(
                "INSERT OR REPLACE INTO tasks VALUES (?, ?, ?, ?)", (kind, key, status, _now())
            )

    def clear_tasks(self, kind: str) -> None:
        with self.conn:
            self.conn.execute("DELETE FROM tasks WHERE kind = ?", (kind,))

    # -- runs ------------------------------------------------------------------------------
    def start_run(self, command: str, args: dict) -> int:
        with self.conn:
            cur = self.conn.execute(
                "INSERT INTO runs (command, args, started, status) VALUES (?, ?, ?, 'running')",
                (command, json.dumps(args, default=str), _now()),
            )
        return int(cur.lastrowid or 0)

    def finish_run(self, run: int, status: str, summary: dict | None = None) -> None:
        with self.conn:
            self.conn.execute(
                "UPDATE runs SET finished = ?, status = ?, summary = ? WHERE id = ?",
                (_now(), status, json.dumps(summary or {}, default=str), run),
            )

    def runs(self) -> list[dict]:
        rows = self.conn.execute(
            "SELECT id, command, args, started, finished, status, summary FROM runs ORDER BY id"
        ).fetchall()
        keys = ("id", "command", "args", "started", "finished", "status", "summary")
        return [dict(zip(keys, r, strict=True)) for r in rows]
