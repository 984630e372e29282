"""Edits made in a GIS come back (issue 9): a GeoPackage that apygis wrote is edited
in place as QGIS does through OGR (rows of the feature tables, GPKG geometry
blobs, the R-tree kept by its triggers), then read or converted back.

The rule (docs/formats/ogr.md, "Edited files"): L_lines / L_areas win, as what
the user sees; L_line_points supplies the exact topology of the lines whose
feature still agrees with it; L_symbols / L_texts are the symbols and texts.
"""

from __future__ import annotations

import logging
import sqlite3
import struct
import subprocess
import sys

import numpy as np
import pyogrio
import pyogrio.raw
import pytest
import shapely
import shapely.affinity

import apygis
from apygis.errors import FormatError
from apygis.model.polylines import export_lines
from apygis.model.records import NO_REF

# --------------------------------------------------------------------------- QGIS, as OGR edits


def _geom(blob):
    if blob is None:
        return None
    envelope = (0, 32, 48, 48, 64)[(blob[3] >> 1) & 7]
    return shapely.from_wkb(bytes(blob[8 + envelope :]))


class Gpkg:
    """A GeoPackage edited in place, feature by feature, as QGIS does through OGR.

    Geometries are GPKG blobs (header, XY envelope, ISO WKB); the R-tree
    triggers GDAL created run with the ST_* functions GDAL registers.
    """

    def __init__(self, path):
        self.db = sqlite3.connect(path)
        f = self.db.create_function
        f("ST_IsEmpty", 1, lambda b: None if b is None else int(_geom(b).is_empty))
        for name, k in (("ST_MinX", 0), ("ST_MinY", 1), ("ST_MaxX", 2), ("ST_MaxY", 3)):
            f(name, 1, lambda b, k=k: None if b is None else float(shapely.bounds(_geom(b))[k]))

    def _blob(self, table, geom):
        (srs,) = self.db.execute(
            "SELECT srs_id FROM gpkg_geometry_columns WHERE table_name = ?", (table,)
        ).fetchone()
        minx, miny, maxx, maxy = shapely.bounds(geom).tolist()
        head = b"GP\x00\x03" + struct.pack("<i4d", srs, minx, maxx, miny, maxy)
        return head + shapely.to_wkb(geom, output_dimension=3, flavor="iso")

    def rows(self, table, *fields):
        cols = ", ".join(["fid", "geom", *(f'"{c}"' for c in fields)])
        got = self.db.execute(f'SELECT {cols} FROM "{table}" ORDER BY fid').fetchall()
        return [(r[0], _geom(r[1]), *r[2:]) for r in got]

    def fid(self, table, field, value):
        (row,) = self.db.execute(f'SELECT fid FROM "{table}" WHERE "{field}" = ?', (value,))
        return row[0]

    def delete(self, table, fid):
        assert self.db.execute(f'DELETE FROM "{table}" WHERE fid = ?', (fid,)).rowcount == 1

    def update(self, table, fid, geom=None, **values):
        if geom is not None:
            values["geom"] = self._blob(table, geom)
        sets = ", ".join(f'"{k}" = ?' for k in values)
        cur = self.db.execute(f'UPDATE "{table}" SET {sets} WHERE fid = ?', (*values.values(), fid))
        assert cur.rowcount == 1

    def insert(self, table, geom, **values):
        values["geom"] = self._blob(table, geom)
        cols = ", ".join(f'"{k}"' for k in values)
        marks = ", ".join("?" * len(values))
        self.db.execute(f'INSERT INTO "{table}" ({cols}) VALUES ({marks})', tuple(values.values()))

    def geometry(self, table, fid):
        return next(g for f, g in self.rows(table) if f == fid)

    def close(self):
        self.db.commit()
        self.db.close()


def _moved(geom, k, dx, dy):
    """``geom`` (a LineString or one-ring Polygon) with vertex ``k`` moved."""
    ring = shapely.get_type_id(geom) == 3
    xyz = shapely.get_coordinates(geom, include_z=True)
    xyz[k, :2] += (dx, dy)
    if ring:
        if k == 0:
            xyz[-1] = xyz[0]
        return shapely.Polygon(xyz)
    return shapely.LineString(xyz)


def _convert(src, dst):
    """``apygis convert SRC DST`` as a user runs it; returns its standard error."""
    done = subprocess.run(
        [sys.executable, "-m", "apygis", "convert", str(src), str(dst)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stderr


def _polylines(lay):
    """{vertex coordinates (rounded to 0.1 mm): point numbers} of every line of a layer."""
    return {
        tuple(map(tuple, np.round(pl.coords, 4))): pl.nums
        for pl in export_lines(lay)
        if len(pl.nums) >= 2 or pl.closed
    }


def _key(geom):
    xyz = shapely.get_coordinates(geom, include_z=True)
    if shapely.get_type_id(geom) == 3:
        xyz = xyz[:-1]
    return tuple(map(tuple, np.round(xyz, 4)))


def _rows(lay, nums):
    lp = lay.line_points
    return {int(r["num"]): r.tolist() for r in lp[np.isin(lp["num"], list(nums))]}


def _at(lay, xyz):
    """Point numbers of the line points at ``xyz`` (X, Y to 0.1 mm)."""
    lp = lay.line_points
    hit = (np.abs(lp["x"] - xyz[0]) < 1e-4) & (np.abs(lp["y"] - xyz[1]) < 1e-4)
    return lp["num"][hit].tolist()


def _edit_report(caplog):
    return [r.getMessage() for r in caplog.records if "edits taken" in r.getMessage()]


# --------------------------------------------------------------------------- lines


def test_lines_deleted_moved_added_come_back_through_convert(sample_map, tmp_path):
    gpkg = tmp_path / "ZH1091.gpkg"
    apygis.write(sample_map, gpkg)
    r0 = sample_map.layers["r"]
    g = Gpkg(gpkg)
    # delete the lone road 101..112
    g.delete("r_lines", g.fid("r_lines", "points", ",".join(map(str, range(101, 113)))))
    # move a vertex of the road 65..83 (a branch ending at 6 on the main road, and the
    # junction 71 of the branch 15,41..64)
    bent_fid = g.fid("r_lines", "points", ",".join(map(str, [*range(65, 84), 6])))
    bent = _moved(g.geometry("r_lines", bent_fid), 2, 2.0, 1.0)
    g.update("r_lines", bent_fid, bent)
    # draw a new road (points NULL) ending on vertex 30 of the main road
    p30 = r0.line_points[r0.line_points["num"] == 30][0]
    new = shapely.LineString(
        [(2684500.0, 1247300.0, 440.0), (2684450.0, 1247350.0, 441.0), tuple(p30[["x", "y", "z"]])]
    )
    g.insert("r_lines", new, code=14)
    g.close()

    err = _convert(gpkg, tmp_path / "out" / "ZH1091")
    assert (
        "layer r: edits taken: 1 line changed (topology rebuilt), 1 line added, "
        "1 line deleted (from r_lines); 1 branch end joined again to its rebuilt junction"
    ) in err
    back = apygis.read(tmp_path / "out" / "ZH1091")

    for ext in "ceh":
        assert back.layers[ext] == sample_map.layers[ext]
    r = back.layers["r"]
    assert not r.validate()
    assert r.symbols.tolist() == r0.symbols.tolist()
    assert r.texts.tolist() == r0.texts.tolist()
    c0, c = r0.counts(), r.counts()
    assert c == {**c0, "line_points": c["line_points"]}
    lines = _polylines(r)
    # the changed road: the moved vertex, the junction 6 at its end, the branch at 71 again
    nums = lines[_key(bent)]
    assert nums[-1] == 6
    assert not set(nums[:-1]) & set(range(65, 84))
    (j71,) = _at(r, r0.line_points[r0.line_points["num"] == 71][0].tolist()[1:4])
    assert j71 in nums
    # the new road is a branch of 30
    nums = lines[_key(new)]
    assert nums[-1] == 30
    assert min(nums[:-1]) > 142
    new_end = nums[-2]
    # the deleted road is gone
    assert not np.isin(r.line_points["num"], range(101, 113)).any()
    assert not _at(r, r0.line_points[r0.line_points["num"] == 105][0].tolist()[1:4])
    # every other line keeps its numbers and references, exactly, but for the references
    # to the points that were rebuilt: they name the rebuilt points at the same place
    kept = set(range(1, 65)) | set(range(84, 101)) | set(range(113, 143))
    before, after = _rows(r0, kept), _rows(r, kept)
    assert before.keys() == after.keys()
    assert before[30][7] == NO_REF
    before[30] = (*before[30][:7], new_end, before[30][8])  # side1: the new road
    renamed = {71: j71, 83: nums_end(r, 6)}
    for num, row in before.items():
        want = tuple(renamed.get(v, v) if k >= 5 else v for k, v in enumerate(row))
        assert after[num] == want, num


def nums_end(lay, junction):
    """The line point that hangs on ``junction`` by a side reference (the end of a branch)."""
    (row,) = lay.line_points[lay.line_points["num"] == junction]
    sides = [int(v) for v in (row["side1"], row["side2"]) if v != NO_REF]
    (end,) = [
        v
        for v in sides
        if lay.line_points[lay.line_points["num"] == v][0]["fwd"] == junction
        or lay.line_points[lay.line_points["num"] == v][0]["back"] == junction
    ]
    return end


def test_areas_deleted_moved_added(sample_map, tmp_path, caplog):
    gpkg = tmp_path / "m.gpkg"
    apygis.write(sample_map, gpkg)
    r0 = sample_map.layers["r"]
    g = Gpkg(gpkg)
    g.delete("r_areas", g.fid("r_areas", "points", "117,118,119,120"))
    fid = g.fid("r_areas", "points", "121,122,123,124")
    moved = _moved(g.geometry("r_areas", fid), 0, -1.5, 0.5)  # the first (and last) vertex
    g.update("r_areas", fid, moved)
    pond = shapely.Polygon(
        [(2684600.0, 1247600.0, 1.0), (2684620, 1247600, 2), (2684610, 1247620, 3)]
    )
    g.insert("r_areas", pond, code=22)
    g.close()

    with caplog.at_level(logging.WARNING, logger="apygis.formats.ogr"):
        back = apygis.read(gpkg)
    (msg,) = _edit_report(caplog)
    assert msg.endswith(
        "layer r: edits taken: 1 area changed (topology rebuilt), 1 area added, "
        "1 area deleted (from r_areas)"
    )
    r = back.layers["r"]
    assert not r.validate()
    assert r.counts()["closed_lines"] == r0.counts()["closed_lines"]
    lines = _polylines(r)
    assert len(lines[_key(moved)]) == 4
    assert min(lines[_key(moved)]) > 142
    nums = lines[_key(pond)]
    assert len(nums) == 3
    assert r.closure(nums[0]).closed
    assert set(r.line_points[np.isin(r.line_points["num"], nums)]["code"]) == {22}
    gone = set(range(117, 125))
    kept = set(range(1, 143)) - gone
    assert _rows(r, kept) == _rows(r0, kept)
    assert not np.isin(r.line_points["num"], sorted(gone)).any()


def test_deleted_line_under_kept_branches(sample_map, tmp_path, caplog):
    """Deleting the main road: its branches keep their points and reach where it was."""
    gpkg = tmp_path / "m.gpkg"
    apygis.write(sample_map, gpkg)
    r0 = sample_map.layers["r"]
    g = Gpkg(gpkg)
    g.delete("r_lines", g.fid("r_lines", "points", ",".join(map(str, range(1, 41)))))
    g.close()
    with caplog.at_level(logging.WARNING, logger="apygis.formats.ogr"):
        r = apygis.read(gpkg).layers["r"]
    (msg,) = _edit_report(caplog)
    assert msg.endswith(
        "edits taken: 1 line deleted (from r_lines); "
        "4 branch ends given a new line point where its junction was"
    )
    assert not r.validate()
    assert not np.isin(r.line_points["num"], range(1, 41)).any()
    # the branches 15,41..64,71 / 65..83,6 / 25,84..100,33 look as before: each reaches
    # the place of its junction on the deleted road through a new end point
    before, after = _polylines(r0), _polylines(r)
    for key, nums in before.items():
        if nums[0] in (15, 65, 25):
            got = after[key]
            assert got[1:-1] == nums[1:-1]
    assert r.counts()["line_points"] == r0.counts()["line_points"] - 40 + 4


# --------------------------------------------------------------------------- symbols, texts


def test_symbols_and_texts_deleted_moved_changed_added(sample_map, tmp_path, caplog):
    gpkg = tmp_path / "m.gpkg"
    apygis.write(sample_map, gpkg)
    r0 = sample_map.layers["r"]
    g = Gpkg(gpkg)
    g.delete("r_symbols", g.fid("r_symbols", "num", 2))
    g.update("r_symbols", g.fid("r_symbols", "num", 3), shapely.Point(2684311.0, 1247801.5, 444.0))
    g.update("r_symbols", g.fid("r_symbols", "num", 4), code=41)
    g.insert("r_symbols", shapely.Point(2684000.0, 1248000.0, 450.0), code=9)  # num NULL
    g.insert("r_symbols", shapely.Point(2684001.0, 1248001.0, 451.0))  # code NULL too
    g.delete("r_texts", g.fid("r_texts", "num", 4))
    g.update("r_texts", g.fid("r_texts", "num", 1), shapely.Point(2684240.0, 1247790.0, 443.7))
    g.update("r_texts", g.fid("r_texts", "num", 2), text="Kirchgasse")
    g.insert("r_texts", shapely.Point(2684100.0, 1248100.0, 450.0), text="Neuhof")
    g.close()

    with caplog.at_level(logging.WARNING, logger="apygis.formats.ogr"):
        m = apygis.read(gpkg, default_code=5)
    (msg,) = _edit_report(caplog)
    assert msg.endswith(
        "layer r: edits taken: 2 symbols added (numbered 6, 7) (from r_symbols); "
        "1 text added (numbered 6) (from r_texts)"
    )
    r = m.layers["r"]
    s0 = {int(s["num"]): s.tolist() for s in r0.symbols}
    assert r.symbols.tolist() == [
        s0[1],
        (3, 2684311.0, 1247801.5, 444.0, 28),
        (4, *s0[4][1:4], 41),
        s0[5],
        (6, 2684000.0, 1248000.0, 450.0, 9),
        (7, 2684001.0, 1248001.0, 451.0, 5),
    ]
    t0 = {int(t["num"]): t.tolist() for t in r0.texts}
    assert r.texts.tolist() == [
        (1, 2684240.0, 1247790.0, 443.7, "Hauptstrasse"),
        (2, *t0[2][1:4], "Kirchgasse"),
        t0[3],
        t0[5],
        (6, 2684100.0, 1248100.0, 450.0, "Neuhof"),
    ]
    assert r.line_points.tolist() == r0.line_points.tolist()
    assert not r.validate()


def test_copied_features_get_new_numbers(sample_map, tmp_path, caplog):
    """QGIS's copy and paste copies the attributes: ``num`` and ``points`` too."""
    gpkg = tmp_path / "m.gpkg"
    apygis.write(sample_map, gpkg)
    h0 = sample_map.layers["h"]
    g = Gpkg(gpkg)
    (_, sym, num, code) = g.rows("h_symbols", "num", "code")[0]
    g.insert("h_symbols", shapely.Point(sym.x + 5, sym.y, sym.z), num=num, code=code)
    (_, line, points, code) = g.rows("h_lines", "points", "code")[3]  # 92..100,70
    copy = shapely.affinity.translate(line, 20.0, 0.0)  # moved away: a new line
    g.insert("h_lines", copy, points=points, code=code, npoints=10)
    g.close()
    with caplog.at_level(logging.WARNING, logger="apygis.formats.ogr"):
        h = apygis.read(gpkg).layers["h"]
    (msg,) = _edit_report(caplog)
    assert "1 symbol renumbered (a number an earlier feature has: 1 -> 5)" in msg
    assert "1 line added (from h_lines)" in msg
    assert not h.validate()
    assert h.symbols[:4].tolist() == h0.symbols.tolist()
    assert h.symbols[4]["num"] == 5
    assert h.line_points[: len(h0.line_points)].tolist() == h0.line_points.tolist()
    assert _polylines(h)[_key(copy)][0] > 112


def test_code_changed_rebuilds_the_line(sample_map, tmp_path, caplog):
    gpkg = tmp_path / "m.gpkg"
    apygis.write(sample_map, gpkg)
    h0 = sample_map.layers["h"]
    g = Gpkg(gpkg)
    fid = g.fid("h_lines", "points", "92,93,94,95,96,97,98,99,100,70")
    g.update("h_lines", fid, code=34)
    line = g.geometry("h_lines", fid)
    g.close()
    with caplog.at_level(logging.WARNING, logger="apygis.formats.ogr"):
        h = apygis.read(gpkg).layers["h"]
    (msg,) = _edit_report(caplog)
    assert msg.endswith("edits taken: 1 line changed (topology rebuilt) (from h_lines)")
    assert not h.validate()
    nums = _polylines(h)[_key(line)]
    assert nums[-1] == 70  # a branch of 70 again
    lp = h.line_points
    assert set(lp[np.isin(lp["num"], nums[:-1])]["code"].tolist()) == {34}
    kept = set(range(1, 92)) | set(range(101, 113))
    want = _rows(h0, kept)
    want[70] = (*want[70][:7], nums[-2], want[70][8])  # side1: the rebuilt line's end
    assert _rows(h, kept) == want


def test_line_points_edited_alone_lose_to_lines(sample_map, tmp_path, caplog):
    """A line point moved in L_line_points while L_lines is unchanged: L_lines wins."""
    gpkg = tmp_path / "m.gpkg"
    apygis.write(sample_map, gpkg)
    h0 = sample_map.layers["h"]
    g = Gpkg(gpkg)
    fid = g.fid("h_line_points", "num", 5)
    p = g.geometry("h_line_points", fid)
    g.update("h_line_points", fid, shapely.Point(p.x + 3, p.y, p.z))
    g.close()
    with caplog.at_level(logging.WARNING, logger="apygis.formats.ogr"):
        h = apygis.read(gpkg).layers["h"]
    (msg,) = _edit_report(caplog)
    assert "1 line changed (topology rebuilt) (from h_lines)" in msg
    assert not h.validate()
    assert h.counts() == h0.counts()
    # the main stream as h_lines draws it, with its three tributaries joined again
    before, after = _polylines(h0), _polylines(h)
    assert before.keys() == after.keys()
    assert len(h.branches()) == len(h0.branches())


# --------------------------------------------------------------------------- unedited, errors


def _long_map():
    m = apygis.MapFile("LONG", scale=1000, crs="EPSG:2056")
    lay = m.layer("r")
    t = np.linspace(0, 2 * np.pi, 121)[:-1]
    ring = np.column_stack([2683000 + 50 * np.cos(t), 1247000 + 50 * np.sin(t), 400 + t])
    lay.add_line(ring, code=21, closed=True)  # counter-clockwise: a Shapefile turns it round
    x = 2683100 + np.arange(90.0)
    main = lay.add_line(np.column_stack([x, np.full(90, 1247000.5), np.full(90, 410.0)]), 11)
    spur = lay.add_line([(2683120.0, 1247010.0, 411.0), (2683120.0, 1247005.0, 411.0)], code=12)
    lay.join(spur[-1], main[20])
    return m


@pytest.mark.parametrize("name", ["gpkg", "shp", "geojson", "fgb"])
def test_unedited_files_read_back_exactly_and_quietly(sample_map, tmp_path, caplog, name):
    for m in (sample_map, _long_map()):
        target = tmp_path / m.id / ("m.gpkg" if name == "gpkg" else "")
        apygis.write(m, target, driver=name)
        with caplog.at_level(logging.INFO, logger="apygis.formats.ogr"):
            assert apygis.read(target, driver=name) == m
        assert not _edit_report(caplog)
    if name == "shp":  # the long line's points are cut in the DBF, the ring turned round
        meta, _, _, data = pyogrio.raw.read(tmp_path / "LONG" / "LONG_r_lines.shp")
        assert dict(zip(meta["fields"], data, strict=True))["points"][0].endswith(",...")


def test_bad_points_are_format_errors(sample_map, tmp_path):
    gpkg = tmp_path / "m.gpkg"
    apygis.write(sample_map, gpkg)
    g = Gpkg(gpkg)
    fid = g.fid("h_lines", "points", ",".join(map(str, range(78, 92))) + ",43")
    g.update("h_lines", fid, points="78,79,eighty")
    g.close()
    with pytest.raises(FormatError) as err:
        apygis.read(gpkg)
    assert str(err.value) == (
        f"{gpkg}: layer h_lines: feature {fid}: field points is '78,79,eighty', expected point "
        "numbers like '12,13,14' (or NULL for a new line)"
    )


def test_feature_without_geometry_is_reported(sample_map, tmp_path, caplog):
    gpkg = tmp_path / "m.gpkg"
    apygis.write(sample_map, gpkg)
    g = Gpkg(gpkg)
    g.db.execute("UPDATE h_areas SET geom = NULL")
    g.close()
    with caplog.at_level(logging.WARNING, logger="apygis.formats.ogr"):
        h = apygis.read(gpkg).layers["h"]
    (msg,) = _edit_report(caplog)
    assert msg.endswith("1 feature without geometry skipped, 1 area deleted (from h_areas)")
    assert h.counts()["closed_lines"] == 0
    assert not h.validate()
    assert pyogrio.read_info(gpkg, layer="h_areas")["features"] == 1
