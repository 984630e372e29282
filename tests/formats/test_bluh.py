"""BLUH's record layouts and the map driver of the APY way (`convert MAP x.bluh --to bluh`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner

import apygis
from apygis.cli import main
from apygis.errors import FormatError, ValueRangeError
from apygis.formats import bluh, get_driver
from tests.formats.test_patb import densification_map


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def test_photo_coordinates_round_trip_and_layout():
    photos = [
        (101, [1001, 2147483647], np.array([[-95.12345, 99.9], [0.00004, -0.00006]])),
        (7, [3], np.array([[1.0, 2.0]])),
    ]
    data = bluh.encode_photo_coordinates(photos)
    lines = data.decode().splitlines()
    assert lines[:4] == [
        f"{101:>10}",
        f"{1001:>10}{-95.1235:12.4f}{99.9:12.4f}",
        f"{2147483647:>10}{'0.0000':>12}{'-0.0001':>12}",
        f"{0:>10}",
    ]
    back = bluh.decode_photo_coordinates(data, "p.pho")
    assert [(p.photo, p.numbers) for p in back] == [(101, [1001, 2147483647]), (7, [3])]
    for got, (_, _, xy) in zip(back, photos, strict=True):
        assert np.abs(got.xy_mm - xy).max() <= 0.5e-4 + 1e-12


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"7\n 12 1 2\n", r"photo 7 \(line 1\) is not closed by a record 0"),
        (
            b"7\n 12 1 2\n 12 3 4\n0\n",
            r"line 3: point 12 is measured twice in photo 7 \(also at line 2\)",
        ),
        (
            b"7\n 2147483648 1 2\n0\n",
            r"line 2: point number '2147483648' is not a whole number from 1 to 2147483647",
        ),
        (b"7\n A1 1 2\n0\n", r"line 2: point number 'A1' is not a whole number"),
        (b"7\n 12 1 NaN\n0\n", r"line 2: y \(mm\) 'NaN' is not a finite number"),
    ],
)
def test_photo_coordinates_refusals(data, message):
    with pytest.raises(FormatError, match=r"^p\.pho: " + message):
        bluh.decode_photo_coordinates(data, "p.pho")


def test_control_round_trip_codes_and_refusals():
    pts = [
        (1001, 2600100.0, 1200200.0, 512.3, 3),
        (1002, 2600000.0, 1200000.0, math.nan, 1),
        (1003, 1.0, 2.0, 400.25, 2),
    ]
    data = bluh.encode_control(pts)
    assert (
        data.decode().splitlines()[1]
        == f"{1002:>10}{2600000.0:15.3f}{1200000.0:15.3f}{0.0:12.3f}{1:>3}"
    )
    back = bluh.decode_control(data, "c.ctl")
    assert [(n, c) for n, _, c, _ in back] == [(1001, 3), (1002, 1), (1003, 2)]
    assert math.isnan(back[1][1][2])
    assert back[2][1].tolist() == [1.0, 2.0, 400.25]
    with pytest.raises(
        FormatError, match=r"c\.ctl: line 1: control code '4' is not a whole number from 1 to 3"
    ):
        bluh.decode_control(b"12 1 2 3 4\n0\n", "c.ctl")
    with pytest.raises(FormatError, match=r"c\.ctl: the control file is not closed by a record 0"):
        bluh.decode_control(b"12 1 2 3 3\n", "c.ctl")
    with pytest.raises(
        ValueRangeError, match=r"c\.ctl: point 1: Z 12345678\.0 does not fit the field F12\.3"
    ):
        bluh.encode_control([(1, 0.0, 0.0, 12345678.0, 3)], "c.ctl")


def test_the_driver_writes_point_numbers(tmp_path):
    assert get_driver("bluh").modes == "w"
    m = densification_map()
    apygis.write(m, tmp_path / "d.bluh")
    back = bluh.decode_photo_coordinates((tmp_path / "d.bluh").read_bytes(), "d.bluh")
    assert [p.photo for p in back] == [101, 102, 103]
    assert back[0].numbers == [101, 102, 103, 104, 105, 106, 107, 108, 109]


def test_the_driver_refuses_names_that_are_not_numbers(tmp_path):
    m = densification_map()
    m.layer("e").add_text(1.0, 2.0, 0.0, "103 GCP7")
    with pytest.raises(
        ValueRangeError,
        match=r"map DENS layer e text 10: point name 'GCP7' is not a BLUH point number",
    ):
        apygis.write(m, tmp_path / "d.bluh")
    src = tmp_path / "M.apa"
    apygis.write(m, src)
    res = _run("convert", src, tmp_path / "x.bluh", "--to", "bluh")
    assert res.exit_code == 1
    assert "'GCP7' is not a BLUH point number" in res.output
    assert not (tmp_path / "x.bluh").exists()


def test_convert_to_bluh_through_the_cli(tmp_path):
    src = tmp_path / "DENS.apa"
    apygis.write(densification_map(), src)
    res = _run("convert", src, tmp_path / "x.bluh", "--to", "bluh")
    assert res.exit_code == 0, res.output
    back = bluh.decode_photo_coordinates((tmp_path / "x.bluh").read_bytes(), "x.bluh")
    assert sum(len(p.numbers) for p in back) == 27
