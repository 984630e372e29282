"""Reading DXF files that other programs wrote: content after EOF, polylines with arcs
(bulges)."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

import apygis
from apygis.formats.dxf.read_ezdxf import chord_tolerance

ezdxf = pytest.importorskip("ezdxf")

R = 10.0
TOL = chord_tolerance(1000)  # a DXF without apygis's header: 1:1000, 0.025 m


def _one_line(lay):
    """The coordinates of the layer's only line, and whether it is closed."""
    assert lay.counts()["lines"] == 1
    rows = lay.chains().rows(0)
    lp = lay.line_points[rows]
    xy = np.column_stack([lp["x"], lp["y"]])
    return xy, lay.counts()["closed_lines"] == 1, lp


def _on_circle(xy, cx, cy, r, tol):
    d = np.hypot(xy[:, 0] - cx, xy[:, 1] - cy)
    assert np.all(np.abs(d - r) <= 1e-6), (d.min(), d.max())
    # the chords' midpoints: within tol of the arc (the sagitta)
    q = np.vstack([xy, xy[:1]])
    mid = (q[1:] + q[:-1]) / 2
    dm = np.hypot(mid[:, 0] - cx, mid[:, 1] - cy)
    assert np.all(r - dm <= tol + 1e-9), (r - dm).max()


def _area(lay, lp):
    a, b = (int(v) for v in lp["num"][:2])
    return abs(lay.area(a, b).area_m2)


def _check_circle(path, cx, cy, r, tol=TOL):
    (lay,) = apygis.read(path).layers.values()
    xy, closed, lp = _one_line(lay)
    assert closed
    assert len(xy) > 8
    _on_circle(xy, cx, cy, r, tol)
    # an inscribed polygon whose chords stay within tol of the circle
    assert math.pi * (r - tol) ** 2 <= _area(lay, lp) <= math.pi * r**2 + 1e-6
    assert lay.validate() == []


def test_two_vertex_closed_bulged_lwpolyline_is_a_circle(tmp_path):
    doc = ezdxf.new()
    doc.modelspace().add_lwpolyline(
        [(100 + R, 200, 0, 0, 1), (100 - R, 200, 0, 0, 1)], format="xyseb", close=True
    )
    path = tmp_path / "circle.dxf"
    doc.saveas(path)
    _check_circle(path, 100, 200, R)


def test_clockwise_bulges_and_elevation(tmp_path):
    doc = ezdxf.new()
    pl = doc.modelspace().add_lwpolyline(
        [(R, 0, 0, 0, -1), (-R, 0, 0, 0, -1)], format="xyseb", close=True
    )
    pl.dxf.elevation = 400.0
    path = tmp_path / "cw.dxf"
    doc.saveas(path)
    _check_circle(path, 0, 0, R)
    (lay,) = apygis.read(path).layers.values()
    assert np.all(lay.line_points["z"] == 400.0)


def test_four_bulge_closed_r12_polyline_is_a_circle(tmp_path):
    doc = ezdxf.new("R12")
    b = math.tan(math.pi / 8)  # a quarter circle per segment
    pts = [(R, 0), (0, R), (-R, 0), (0, -R)]
    pl = doc.modelspace().add_polyline2d(pts, close=True)
    for v in pl.vertices:
        v.dxf.bulge = b
    path = tmp_path / "r12.dxf"
    doc.saveas(path)
    assert "AC1009" in path.read_text()
    _check_circle(path, 0, 0, R)


def test_two_vertex_closed_bulged_r12_polyline_is_a_circle(tmp_path):
    doc = ezdxf.new("R12")
    pl = doc.modelspace().add_polyline2d([(5 + R, 7), (5 - R, 7)], close=True)
    for v in pl.vertices:
        v.dxf.bulge = 1.0
    path = tmp_path / "two12.dxf"
    doc.saveas(path)
    _check_circle(path, 5, 7, R)


def test_four_bulge_closed_lwpolyline_follows_its_arcs(tmp_path):
    """Read as straight segments, the line was up to r - r/sqrt(2) = 2.9 m inside the circle."""
    doc = ezdxf.new()
    b = math.tan(math.pi / 8)
    big = 50.0
    doc.modelspace().add_lwpolyline(
        [(big, 0, 0, 0, b), (0, big, 0, 0, b), (-big, 0, 0, 0, b), (0, -big, 0, 0, b)],
        format="xyseb",
        close=True,
    )
    path = tmp_path / "four.dxf"
    doc.saveas(path)
    _check_circle(path, 0, 0, big)


def test_chord_tolerance_option(tmp_path):
    doc = ezdxf.new()
    doc.modelspace().add_lwpolyline([(R, 0, 0, 0, 1), (-R, 0, 0, 0, 1)], format="xyseb", close=True)
    path = tmp_path / "c.dxf"
    doc.saveas(path)
    coarse = len(apygis.read(path, chord_m=0.5).layers["x"].line_points)
    fine = len(apygis.read(path, chord_m=0.001).layers["x"].line_points)
    assert coarse < fine
    (lay,) = apygis.read(path, chord_m=0.001).layers.values()
    xy, closed, _ = _one_line(lay)
    assert closed
    _on_circle(xy, 0, 0, R, 0.001)
    with pytest.raises(apygis.errors.DriverError):
        apygis.read(path, chord_m=0)


def test_chord_tolerance_rule():
    assert chord_tolerance(1000) == pytest.approx(0.025)
    assert chord_tolerance(5000) == pytest.approx(0.125)


def test_open_bulged_polyline_follows_its_arc(tmp_path):
    """A half circle from (R, 0) to (-R, 0) through (0, R): not a straight line of 2 points."""
    doc = ezdxf.new()
    doc.modelspace().add_lwpolyline([(R, 0, 0, 0, 1), (-R, 0)], format="xyseb")
    path = tmp_path / "open.dxf"
    doc.saveas(path)
    lay = apygis.read(path).layers["x"]
    xy, closed, _ = _one_line(lay)
    assert not closed
    assert len(xy) > 8
    assert xy[0].tolist() == [R, 0]
    assert xy[-1].tolist() == [-R, 0]
    d = np.hypot(xy[:, 0], xy[:, 1])
    assert np.all(np.abs(d - R) <= 1e-9)
    assert xy[:, 1].min() >= 0
    assert xy[:, 1].max() == pytest.approx(R, abs=TOL)
    q = (xy[1:] + xy[:-1]) / 2
    assert np.all(R - np.hypot(q[:, 0], q[:, 1]) <= TOL + 1e-9)


def test_open_bulged_r12_polyline_follows_its_arcs(tmp_path):
    doc = ezdxf.new("R12")
    pl = doc.modelspace().add_polyline2d([(R, 0), (0, R), (-R, 0)])
    for v in list(pl.vertices)[:2]:
        v.dxf.bulge = math.tan(math.pi / 8)
    path = tmp_path / "open12.dxf"
    doc.saveas(path)
    lay = apygis.read(path).layers["x"]
    xy, closed, _ = _one_line(lay)
    assert not closed
    assert len(xy) > 8
    assert np.all(np.abs(np.hypot(xy[:, 0], xy[:, 1]) - R) <= 1e-9)


# --------------------------------------------------------------------------- after EOF


def _with_garbage(tmp_path, garbage: bytes):
    doc = ezdxf.new()
    msp = doc.modelspace()
    msp.add_line((0, 0, 0), (10, 0, 0))
    msp.add_point((5, 5, 1))
    path = tmp_path / "garbage.dxf"
    doc.saveas(path)
    data = path.read_bytes()
    path.write_bytes(data + garbage)
    return path


GARBAGE = b"\x00\x00some bytes a mailer added\nand another line\n  0\nLINE\n"


def test_content_after_eof_is_ignored_with_a_warning(tmp_path, caplog):
    path = _with_garbage(tmp_path, GARBAGE)
    with caplog.at_level(logging.WARNING, logger="apygis.formats.dxf"):
        m = apygis.read(path)
    lay = m.layers["x"]
    assert len(lay.line_points) == 2
    assert len(lay.symbols) == 1
    assert f"{len(GARBAGE)} bytes (4 lines) after the tags 0 and EOF ignored" in caplog.text
    assert str(path) in caplog.text
    assert "truncated" not in caplog.text


def test_only_whitespace_after_eof_says_nothing(tmp_path, caplog):
    path = _with_garbage(tmp_path, b"\n\n  \r\n\x1a")
    with caplog.at_level(logging.WARNING, logger="apygis.formats.dxf"):
        apygis.read(path)
    assert "after the tags 0 and EOF" not in caplog.text


def test_a_file_cut_short_is_still_refused(tmp_path):
    path = _with_garbage(tmp_path, b"")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(apygis.errors.FormatError, match="truncated"):
        apygis.read(path)


def test_info_of_a_file_with_content_after_eof(tmp_path):
    """`apygis info` (its own process, so that its logging is set up as a user's)."""
    import subprocess
    import sys

    path = _with_garbage(tmp_path, GARBAGE)
    res = subprocess.run(
        [sys.executable, "-m", "apygis", "info", str(path)], capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr
    assert "54 bytes (4 lines) after the tags 0 and EOF ignored" in res.stderr
    assert "truncated" not in res.stderr + res.stdout
    assert "garbage" in res.stdout
