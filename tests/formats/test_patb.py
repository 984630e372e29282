"""PAT-B's record layouts and the map driver of the APY way (`convert MAP x.patb --to patb`)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import apygis
from apygis.cli import main
from apygis.errors import FormatError, ValueRangeError
from apygis.formats import driver_for, get_driver, patb
from apygis.orient.rotation import rotation_matrix


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def densification_map() -> apygis.MapFile:
    """The seed's densification: nine points per photo measured on the tablet (photo mm),
    compiled as texts 'PHOTO POINT' in two layers."""
    m = apygis.MapFile("DENS")
    rng = np.random.default_rng(7)
    grid = [(-90.0, 90.0), (0.0, 90.0), (90.0, 90.0), (-90.0, 0.0), (0.0, 0.0), (90.0, 0.0),
            (-90.0, -90.0), (0.0, -90.0), (90.0, -90.0)]  # fmt: skip
    for photo, ext in ((101, "c"), (102, "c"), (103, "e")):
        lay = m.layer(ext)
        for k, (x, y) in enumerate(grid):
            name = f"{photo - 100}{k + 1:02d}"  # points transferred between photos share names
            lay.add_text(x + rng.normal(0, 3), y + rng.normal(0, 3), 0.0, f"{photo} {name}")
    return m


# ------------------------------------------------------------------ layouts


def test_image_coordinates_round_trip_and_layout():
    photos = [
        (
            101,
            ["1001", "GCP-7", "A" * 15],
            np.array([[-95.1234567, 99.9], [0.0004, -0.0006], [113.5, -114.25]]),
        ),
        (7, ["1001"], np.array([[1.0, 2.0]])),
    ]
    data = patb.encode_image_coordinates(photos)
    lines = data.decode().splitlines()
    assert lines[0] == f"{101:>16}"
    assert lines[1] == f"{'1001':>16}{-95123.457:16.3f}{99900.0:16.3f}"
    assert lines[2] == f"{'GCP-7':>16}{'0.400':>16}{'-0.600':>16}"
    assert lines[4] == f"{-99:>16}"
    assert all(len(line) <= 48 for line in lines)
    back = patb.decode_image_coordinates(data, "x.im")
    assert [(p.photo, p.names) for p in back] == [(p, n) for p, n, _ in photos]
    for got, (_, _, xy) in zip(back, photos, strict=True):
        assert np.abs(got.xy_mm - xy).max() <= 0.5e-6 + 1e-12  # micrometres, 3 decimals


def test_image_coordinates_read_other_alignments():
    data = b"101\n  P1 -12.5 3\n\n\tP2\t4\t5\n-99\n7\n-99\n"
    back = patb.decode_image_coordinates(data, "x.im")
    assert [(p.photo, p.names, p.xy_mm.tolist(), p.lines) for p in back] == [
        (101, ["P1", "P2"], [[-0.0125, 0.003], [0.004, 0.005]], [2, 4]),
        (7, [], [], []),
    ]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"101\n P1 1 2\n", r"photo 101 \(line 1\) is not closed by -99"),
        (
            b"101\n P1 1 2\n P1 3 4\n-99\n",
            r"line 3: point 'P1' is measured twice in photo 101 \(also at line 2\)",
        ),
        (b"101\n-99\n101\n-99\n", r"line 3: photo 101 appears again \(first at line 1\)"),
        (
            b"101 5\n-99\n",
            r"line 1: expected a photo record \(the photo number alone\), found 2 fields",
        ),
        (b"101\n P1 1 2 3\n-99\n", r"line 2: expected a point record .* found 4 fields"),
        (
            b"101\n ABCDEFGHIJKLMNOP 1 2\n-99\n",
            r"line 2: point name 'ABCDEFGHIJKLMNOP' has 16 characters",
        ),
        (
            b"101\n P1 1234567.12345-123456.12345 2\n-99\n",
            r"line 2: x \(um\) '1234567\.12345-123456\.\.\.' is not a finite number",
        ),
        (b"101\n P1 1.5.3 2\n-99\n", r"line 2: x \(um\) '1\.5\.3' is not a finite number"),
        (b"0\n-99\n", r"line 1: photo number '0' is not a whole number from 1"),
    ],
)
def test_image_coordinates_refusals(data, message):
    with pytest.raises(FormatError, match=r"^x\.im: " + message):
        patb.decode_image_coordinates(data, "x.im")


def test_writing_refuses_what_does_not_fit():
    with pytest.raises(
        ValueRangeError,
        match=r"t\.im: photo 1 point 'ABCDEFGHIJKLMNOP': point name .* 16 characters",
    ):
        patb.encode_image_coordinates([(1, ["ABCDEFGHIJKLMNOP"], np.zeros((1, 2)))], "t.im")
    with pytest.raises(ValueRangeError, match=r"holds a blank"):
        patb.encode_image_coordinates([(1, ["A B"], np.zeros((1, 2)))], "t.im")
    with pytest.raises(FormatError, match=r"point name '-99' is PAT-B's end record"):
        patb.encode_image_coordinates([(1, ["-99"], np.zeros((1, 2)))], "t.im")
    with pytest.raises(
        FormatError, match=r"photo number 1000000000000000 is not from 1 to 999999999999999"
    ):
        patb.encode_image_coordinates([(10**15, ["A"], np.zeros((1, 2)))], "t.im")
    with pytest.raises(
        ValueRangeError,
        match=r"t\.im: photo 1 point 'A': x \(um\) 1000000000000000\.0 does not fit the field "
        r"F16\.3",
    ):
        patb.encode_image_coordinates([(1, ["A"], np.array([[1e12, 0.0]]))], "t.im")
    with pytest.raises(ValueRangeError, match=r"t\.con: point 'G': Z nan is not a finite number"):
        patb.encode_control([("G", 1.0, 2.0, float("nan"))], "t.con")


def test_control_round_trip_and_refusals():
    pts = [("GCP1", 2600100.0004, 1200200.9996, 512.3), ("7", -1.0, 0.0, -0.0004)]
    data = patb.encode_control(pts)
    assert data.decode().splitlines()[-1] == f"{-99:>16}"
    back = patb.decode_control(data, "c.con")
    assert [n for n, _, _ in back] == ["GCP1", "7"]
    assert (
        np.abs(np.array([x.tolist() for _, x, _ in back]) - np.array([p[1:] for p in pts])).max()
        <= 0.0005
    )
    with pytest.raises(FormatError, match=r"c\.con: the control file is not closed by -99"):
        patb.decode_control(b"G 1 2 3\n", "c.con")
    with pytest.raises(FormatError, match=r"c\.con: line 3: a record after the closing -99"):
        patb.decode_control(b"G 1 2 3\n-99\nH 1 2 3\n", "c.con")
    with pytest.raises(FormatError, match=r"c\.con: line 2: control point 'G' is given twice"):
        patb.decode_control(b"G 1 2 3\nG 1 2 3\n-99\n", "c.con")


def test_orientations_round_trip_fields_and_refusals():
    R = rotation_matrix(0.01, -0.02, 3.1)
    data = patb.encode_orientations([(101, [2600123.45678, 1200456.78912, 1725.0], R)])
    l1, l2, l3 = data.decode().splitlines()
    assert (
        l1 == f"{101:>16}{'':16}{2600123.45678:16.5f}{1200456.78912:16.5f}{1725.0:16.5f}"
    )  # I16,16X,3F16.5
    assert l2 == "".join(f"{v:16.12f}" for v in R.ravel()[:5])  # 5F16.12
    assert l3 == "".join(f"{v:16.12f}" for v in R.ravel()[5:])  # 4F16.12
    (o,) = patb.decode_orientations(data, "o.ori")
    assert o.photo == 101
    assert np.abs(o.rotation - R).max() <= 0.5e-12
    with pytest.raises(FormatError, match=r"o\.ori: line 1: an orientation needs three records"):
        patb.decode_orientations(b"\n".join(data.splitlines()[:2]), "o.ori")
    bad = data.replace(
        l2.encode(), ("".join(f"{v:16.12f}" for v in [1.0, 0.0, 0.0, 0.0, 1.5]).encode())
    )
    with pytest.raises(
        FormatError, match=r"o\.ori: line 2: the matrix of photo 101 is not a rotation"
    ):
        patb.decode_orientations(bad, "o.ori")
    with pytest.raises(
        ValueRangeError, match=r"o\.ori: photo 101: X0 10000000000\.0 does not fit the field F16\.5"
    ):
        patb.encode_orientations([(101, [1e10, 0.0, 0.0], R)], "o.ori")


# ------------------------------------------------------------------ the map driver


def test_the_driver_is_registered_write_only():
    drv = get_driver("patb")
    assert drv.modes == "w"
    assert drv.extensions == ("patb", "im")
    assert driver_for("out/x.patb", "w").name == "patb"


def test_the_driver_writes_the_densification_map(tmp_path):
    m = densification_map()
    apygis.write(m, tmp_path / "d.patb")
    back = patb.decode_image_coordinates((tmp_path / "d.patb").read_bytes(), "d.patb")
    assert [p.photo for p in back] == [101, 102, 103]
    texts = {}
    for lay in m:
        for x, y, t in zip(lay.texts["x"], lay.texts["y"], lay.texts["text"], strict=True):
            photo, name = t.split()
            texts[(int(photo), name)] = (x, y)
    got = {
        (p.photo, n): tuple(xy)
        for p in back
        for n, xy in zip(p.names, p.xy_mm.tolist(), strict=True)
    }
    assert got.keys() == texts.keys()
    assert (
        max(max(abs(a - b) for a, b in zip(got[k], texts[k], strict=True)) for k in got)
        <= 0.5e-6 + 1e-12
    )


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda m: setattr(m, "crs", "EPSG:2056"),
            r"map DENS: the map has a CRS \(EPSG:2056\): a bundle measurement map",
        ),
        (
            lambda m: m.layer("c").add_symbol(1.0, 2.0, 0.0, 5),
            r"map DENS: layer c holds 1 symbols: a bundle measurement map holds only texts",
        ),
        (
            lambda m: m.layer("r").add_line([(0, 0, 0), (1, 1, 0)], 3),
            r"map DENS: layer r holds 2 line points",
        ),
        (
            lambda m: m.layer("c").add_text(1.0, 2.0, 0.0, "101"),
            r"map DENS layer c text 19: text '101' is not a bundle measurement: "
            r"expected 'PHOTO POINT'",
        ),
        (
            lambda m: m.layer("c").add_text(1.0, 2.0, 0.0, "0101 P"),
            r"layer c text 19: text '0101 P': photo number '0101' is not a whole number .* "
            r"without leading zeros",
        ),
        (
            lambda m: m.layer("c").add_text(2684000.0, 2.0, 0.0, "101 P"),
            r"layer c text 19: text '101 P': X = 2684000\.0 is not a photo coordinate in mm",
        ),
        (
            lambda m: m.layer("e").add_text(1.0, 2.0, 0.0, "103 301"),
            r"map DENS layer e text 10: point '301' is measured twice in photo 103 "
            r"\(also at layer e text 1\)",
        ),
    ],
)
def test_the_driver_refuses_what_is_not_a_bundle_measurement(edit, message, tmp_path):
    m = densification_map()
    edit(m)
    with pytest.raises(FormatError, match=message):
        apygis.write(m, tmp_path / "d.patb")
    assert not (tmp_path / "d.patb").exists()


def test_an_empty_map_is_no_bundle_file(tmp_path):
    m = apygis.MapFile("E")
    m.layer("c")
    with pytest.raises(FormatError, match="map E: the map holds no bundle measurements"):
        apygis.write(m, tmp_path / "e.patb")


def test_convert_to_patb_through_the_cli(tmp_path):
    src = tmp_path / "DENS.apa"
    apygis.write(densification_map(), src)
    out = tmp_path / "out"
    out.mkdir()
    res = _run("convert", src, out / "x.patb", "--to", "patb")
    assert res.exit_code == 0, res.output
    assert "x.patb: 2 layers, 27 records" in res.output
    want = patb.encode_image_coordinates(
        [(p.photo, p.names, p.xy_mm) for p in _photos(apygis.read(src))], "x"
    )
    assert (out / "x.patb").read_bytes() == want
    res = _run("convert", src, out / "x.patb", "--to", "patb")
    assert res.exit_code == 1
    assert "exists; use --overwrite" in res.output
    # --driver names it too, and a folder DST (a trailing slash) receives it under its name
    assert _run("convert", src, out / "y.im", "--driver", "patb").exit_code == 0
    assert _run("convert", "--to", "patb", src, f"{out / 'batch'}/").exit_code == 0
    assert (out / "batch" / "DENS.patb").read_bytes() == want


def test_convert_refusals_are_one_line(tmp_path):
    m = densification_map()
    m.layer("c").add_text(1.0, 2.0, 0.0, "101")
    src = tmp_path / "BAD.apa"
    apygis.write(m, src)
    res = _run("convert", src, tmp_path / "x.patb", "--to", "patb")
    assert res.exit_code == 1
    assert res.output.strip().count("\n") == 0
    assert "map DENS layer c text 19: text '101' is not a bundle measurement" in res.output
    assert not (tmp_path / "x.patb").exists()
    res = _run("convert", tmp_path / "x.patb", tmp_path / "y.apa", "--src-driver", "patb")
    assert res.exit_code == 1
    assert "the patb driver cannot read" in res.output


def _photos(m):
    from apygis.formats._bundlemap import photo_measurements

    return photo_measurements(m, max_photo=patb.MAX_PHOTO)
