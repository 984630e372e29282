"""Readers of the orientation input files: good files, bad lines named, fuzz."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from apygis.errors import FormatError, MeasurementError, OrientationError
from apygis.orient.readers import (
    control_for,
    read_control,
    read_map_measurements,
    read_photo_file,
    read_photo_measurements,
)


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_control(tmp_path):
    p = _write(
        tmp_path, "c.txt", "# header\n\n101 2683000.5 1248000.25 512.3  # trig\n9001\t1 2 -\n"
    )
    c = read_control(p)
    assert c["101"] == (2683000.5, 1248000.25, 512.3)
    assert math.isnan(c["9001"][2])
    assert list(c) == ["101", "9001"]


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("101 1 2\n", 1, "expected 4 fields"),
        ("# c\n101 1 2 3\n102 1 x 3\n", 3, "Y must be a number, got 'x'"),
        ("101 1 2 3\n101 4 5 6\n", 2, "point 101 appears twice \\(first on line 1\\)"),
        ("101 1 2 nan\n", 1, "Z \\(or '-'\\) must be a finite number"),
        ("101 1 2 3 4\n", 1, "expected 4 fields"),
    ],
)
def test_control_errors_name_file_and_line(tmp_path, text, line, match):
    p = _write(tmp_path, "ctrl.txt", text)
    with pytest.raises(FormatError, match=match) as ei:
        read_control(p)
    assert f"ctrl.txt: line {line}:" in str(ei.value)
    assert ei.value.record == f"line {line}"


def test_undecodable_bytes_are_named(tmp_path):
    p = tmp_path / "c.txt"
    p.write_bytes(b"101 1 2 3\n102 1 2 \xe9\n")
    with pytest.raises(FormatError, match="line 2: not UTF-8"):
        read_control(p)


def test_map_measurements(tmp_path):
    p = _write(tmp_path, "m.txt", "1 10.5 20.25\n1 10.51 20.24\n2 100 200\n")
    ids, xy = read_map_measurements(p)
    assert ids == ["1", "1", "2"]
    assert xy.shape == (3, 2)
    p = _write(tmp_path, "m.txt", "1 10.5 20.25\n2 100\n")
    with pytest.raises(FormatError, match=r"m.txt: line 2: expected 3 fields"):
        read_map_measurements(p)
    p = _write(tmp_path, "e.txt", "# nothing\n")
    ids, xy = read_map_measurements(p)
    assert ids == []
    assert xy.shape == (0, 2)


def test_photo_measurements(tmp_path):
    p = _write(tmp_path, "pm.txt", "201 4711 0.1 -0.2\n202 4711 0.3 0.4\n201 4712 -1 1\n")
    m = read_photo_measurements(p)
    assert m["4711"][0] == ["201", "202"]
    np.testing.assert_allclose(m["4712"][1], [[-1.0, 1.0]])
    p = _write(tmp_path, "pm.txt", "201 4711 0.1 -0.2\n201 4711 0.1 -0.2\n")
    with pytest.raises(FormatError, match="line 2: point 201 in photo 4711 appears twice"):
        read_photo_measurements(p)
    p = _write(tmp_path, "pm.txt", "201 4711 0.1 inf\n")
    with pytest.raises(FormatError, match="line 1: py_mm must be a finite number"):
        read_photo_measurements(p)


def test_photo_file(tmp_path):
    p = _write(
        tmp_path,
        "photos.txt",
        "# photos\n"
        "4711 153.0 frame Xo~2683520 Yo~1247780 Zo=2758.6 kappa_gon~200 sx=0.0668 sy=0.0667\n"
        "4712 152.5 scanned sin_omega=0.0001 sin_phi=0.0001 Yo=5 x0_mm=0.01 kappa_deg~0.1\n",
    )
    a, b = read_photo_file(p)
    assert a.photo_id == "4711"
    assert a.interior.focal_mm == 153.0
    assert not a.interior.scanned
    assert a.known == {"Zo": 2758.6, "sx": 0.0668, "sy": 0.0667}
    assert a.approx["kappa"] == pytest.approx(math.pi)
    assert b.interior.scanned
    assert b.interior.x0_mm == 0.01
    assert b.known["omega"] == pytest.approx(math.asin(0.0001))
    assert "Yo" not in b.known  # no meaning for scanned imagery
    assert a.line == 2
    assert b.line == 3
    G = np.array([[2683500.0, 1247800.0, 500.0], [2684000.0, 1247900.0, 520.0]])
    po, fixed = a.approximation(G)
    assert fixed == {"Zo", "sx", "sy"}
    assert po.exterior.Zo == 2758.6
    assert po.exterior.Xo == 2683520.0


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("4711 153\n", "expected 'PHOTO_ID FOCAL_MM"),
        ("4711 -153 frame\n", "FOCAL_MM must be positive"),
        ("4711 153 film\n", "'frame' or 'scanned'"),
        ("4711 153 frame Xo:5\n", "expected KEY=VALUE or KEY~VALUE"),
        ("4711 153 frame zeta=5\n", "unknown key 'zeta'"),
        ("4711 153 frame omega_gon=1 omega_rad~2\n", "omega is given twice"),
        ("4711 153 frame sin_phi=2\n", "sin_phi must lie in"),
        ("4711 153 frame sin_phi~0.1\n", "sin_phi takes '=' only"),
        ("4711 153 frame Zo=abc\n", "Zo must be a number"),
        ("4711 153 frame\n4711 153 frame\n", "photo 4711 appears twice"),
    ],
)
def test_photo_file_errors(tmp_path, text, match):
    p = _write(tmp_path, "ph.txt", text)
    with pytest.raises(FormatError, match=match) as ei:
        read_photo_file(p)
    assert "ph.txt: line " in str(ei.value)


def test_photo_file_empty_and_missing_scale(tmp_path):
    with pytest.raises(FormatError, match="no photo"):
        read_photo_file(_write(tmp_path, "e.txt", "# none\n"))
    (e,) = read_photo_file(_write(tmp_path, "p.txt", "1 153 frame\n"))
    with pytest.raises(OrientationError, match="give Zo"):
        e.approximation(np.array([[0.0, 0.0, 500.0]]))


def test_control_for():
    ctrl = {"1": (1.0, 2.0, 3.0), "2": (4.0, 5.0, math.nan)}
    np.testing.assert_allclose(control_for(["1"], ctrl), [[1, 2, 3]])
    with pytest.raises(MeasurementError, match="point 3 \\(photo P\\) is not in the control"):
        control_for(["3"], ctrl, "P")
    with pytest.raises(MeasurementError, match="has no height"):
        control_for(["2"], ctrl)


_lines = st.lists(
    st.lists(
        st.one_of(
            st.sampled_from(
                ["101", "1.5", "-", "nan", "x", "#", "frame", "scanned", "Zo=1", "sx~0.07", "é"]
            ),
            st.text(max_size=5),
        ),
        max_size=7,
    ).map(" ".join),
    max_size=8,
).map("\n".join)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    _lines,
    st.sampled_from(
        [read_control, read_map_measurements, read_photo_file, read_photo_measurements]
    ),
)
def test_fuzz_readers_raise_only_format_errors(tmp_path, text, reader):
    p = tmp_path / "fuzz.txt"
    p.write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        reader(p)
    except FormatError as exc:
        message = str(exc)
    else:
        message = "fuzz.txt"
    assert "fuzz.txt" in message


_ids = st.text(alphabet="0123456789ABCabc_-.", min_size=1, max_size=8)
_coord = st.floats(-1e7, 1e7, allow_nan=False, allow_infinity=False)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(st.dictionaries(_ids, st.tuples(_coord, _coord, st.one_of(st.none(), _coord)), max_size=10))
def test_control_round_trip(tmp_path, points):
    lines = ["# generated"]
    for pid, (X, Y, Z) in points.items():
        lines.append(f"{pid} {X!r} {Y!r} {'-' if Z is None else repr(Z)}")
    p = tmp_path / "rt.txt"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    back = read_control(p)
    assert list(back) == list(points)
    for pid, (X, Y, Z) in points.items():
        bX, bY, bZ = back[pid]
        assert (bX, bY) == (X, Y)
        assert (Z is None and math.isnan(bZ)) or bZ == Z
