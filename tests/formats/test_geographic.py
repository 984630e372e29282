"""Maps in a geographic CRS (degrees) or in feet: what each format can hold, sizes, tolerances."""

from __future__ import annotations

import json
import re

import ezdxf
import numpy as np
import pytest
from click.testing import CliRunner

import apygis
from apygis.cli import main
from apygis.errors import FormatError
from apygis.formats import e00

# LV95 with the same projection in international and in US survey feet
LV95_FT = (
    "+proj=somerc +lat_0=46.9524055555556 +lon_0=7.43958333333333 +k_0=1 "
    "+x_0=2600000 +y_0=1200000 +ellps=bessel "
    "+towgs84=674.374,15.056,405.346,0,0,0,0 +units=ft +no_defs"
)
LV95_USFT = LV95_FT.replace("+units=ft", "+units=us-ft")


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _one_line_error(res, *parts):
    assert res.exit_code == 1, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1, res.output
    assert "Traceback" not in res.output
    for p in parts:
        assert p in lines[0], lines[0]
    return lines[0]


# --------------------------------------------------------------------------- item 1


@pytest.mark.parametrize(
    ("name", "what"),
    [("x.apa", "APY ASCII stores coordinates in hundredths"), ("x", "APY binary stores")],
)
def test_centimetre_formats_refuse_degrees(sample_dir, tmp_path, name, what):
    target = tmp_path / name
    res = _run("convert", sample_dir / "ZH1091", target, "--to-crs", "EPSG:4326")
    line = _one_line_error(res, str(target), what, "EPSG:4326 is in degrees", "0.01°", "km")
    assert "choose a projected CRS" in line
    assert list(tmp_path.iterdir()) == []  # nothing written, nothing rounded


def test_centimetre_formats_take_feet(sample_dir, tmp_path):
    m = apygis.read(sample_dir / "ZH1091")
    res = _run("convert", sample_dir / "ZH1091", tmp_path / "ft.apa", "--to-crs", LV95_FT)
    assert res.exit_code == 0, res.output
    back = apygis.read(tmp_path / "ft.apa")
    lp, lp0 = back.layers["r"].line_points, m.layers["r"].line_points
    # 0.01 ft = 3 mm: the metres come back to within 2 mm
    np.testing.assert_allclose(lp["x"] * 0.3048, lp0["x"], atol=0.002)


def test_generate_writes_degrees_with_enough_decimals(sample_dir, tmp_path):
    m = apygis.read(sample_dir / "ZH1091")
    res = _run("convert", sample_dir / "ZH1091", tmp_path / "g.gen", "--to-crs", "EPSG:4326")
    assert res.exit_code == 0, res.output
    text = (tmp_path / "g_r_lines.gen").read_text()
    assert re.search(r"\b8\.\d{9}\b", text)  # longitudes with 9 decimals: 0.1 mm
    back = apygis.read(tmp_path / "g.gen")
    from apygis.model.reproject import reproject

    want = reproject(m, "EPSG:4326").layers["c"].symbols
    got = back.layers["c"].symbols
    np.testing.assert_allclose(got["x"], want["x"], atol=1e-9)  # 0.1 mm
    # decimals that cannot hold centimetres in degrees are refused
    w = reproject(m, "EPSG:4326")
    with pytest.raises(FormatError, match=r"GENERATE is written with 3 decimals.*0.001°"):
        apygis.write(w, tmp_path / "h.gen", decimals=3)


def test_e00_degrees_double_kept_single_refused(sample_dir, tmp_path):
    res = _run("convert", sample_dir / "ZH1091", tmp_path / "d.e00", "--to-crs", "EPSG:4326")
    assert res.exit_code == 0, res.output
    from apygis.model.reproject import reproject

    w = reproject(apygis.read(sample_dir / "ZH1091"), "EPSG:4326")
    back = apygis.read(tmp_path / "d.e00")
    got, want = back.layers["r"].line_points["x"], w.layers["r"].line_points["x"]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)  # 15 digits: nanometres
    with pytest.raises(FormatError, match=r"single precision.*degrees.*write double precision"):
        apygis.write(w, tmp_path / "s.e00", precision=e00.SINGLE)
    assert not (tmp_path / "s.e00").exists()


# --------------------------------------------------------------------------- item 3


def _texts_and_block(path):
    doc = ezdxf.readfile(path)
    heights = {round(e.dxf.height, 12) for e in doc.modelspace() if e.dxftype() == "TEXT"}
    blk = next(b for b in doc.blocks if b.name.startswith("APY_SYM_"))
    xs = [v[0] for e in blk if e.dxftype() == "SOLID" for v in e.vertices()]
    return doc.header["$INSUNITS"], doc.header["$MEASUREMENT"], heights, max(xs) - min(xs)


def test_dxf_sizes_in_degrees(sample_dir, tmp_path):
    m = apygis.read(sample_dir / "ZH1091")
    res_m = _run("convert", sample_dir / "ZH1091", tmp_path / "m.dxf")
    res = _run("convert", sample_dir / "ZH1091", tmp_path / "d.dxf", "--to-crs", "EPSG:4326")
    assert res_m.exit_code == 0, res_m.output
    assert res.exit_code == 0, res.output
    units_m, _, heights_m, block_m = _texts_and_block(tmp_path / "m.dxf")
    units, meas, heights, block = _texts_and_block(tmp_path / "d.dxf")
    assert units_m == 6
    assert heights_m == {2.5 * m.scale / 1000}
    assert units == 0  # DXF has no unit for degrees: unitless
    assert meas == 1
    (h,) = heights
    # 12.5 m on the ground at 47.2° N is about 0.000112° of latitude
    assert h == pytest.approx(12.5 / 111_180, rel=2e-3)
    assert block == pytest.approx(block_m / 111_180, rel=2e-3)
    back = apygis.read(tmp_path / "d.dxf")  # still the same map
    assert back.crs.to_epsg() == 4326
    assert sum(len(lay) for lay in back) == sum(len(lay) for lay in m)


@pytest.mark.parametrize(("crs", "code", "foot"), [(LV95_FT, 2, 0.3048), (LV95_USFT, 21, None)])
def test_dxf_sizes_in_feet(sample_dir, tmp_path, crs, code, foot):
    foot = foot or 1200 / 3937
    res = _run("convert", sample_dir / "ZH1091", tmp_path / "f.dxf", "--to-crs", crs)
    assert res.exit_code == 0, res.output
    units, meas, heights, _ = _texts_and_block(tmp_path / "f.dxf")
    assert (units, meas) == (code, 0)
    (h,) = heights
    assert h == pytest.approx(12.5 / foot, rel=1e-9)


# --------------------------------------------------------------------------- item 2


def _lonlat_geojson(path, gap_m):
    """Two roads, the second starting ``gap_m`` metres east of the first one's end (47° N)."""
    deg = gap_m / 76_056.0  # metres of a degree of longitude at 47° N (WGS 84)
    a = [[8.0, 47.0], [8.001, 47.0]]
    b = [[8.001 + deg, 47.0], [8.002 + deg, 47.0]]
    feats = [
        {
            "type": "Feature",
            "properties": {"code": 11},
            "geometry": {"type": "LineString", "coordinates": c},
        }
        for c in (a, b)
    ]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))


@pytest.mark.parametrize(("gap_m", "joined"), [(300.0, False), (0.001, True), (0.05, False)])
def test_snap_tolerance_is_metres_in_lonlat(tmp_path, gap_m, joined):
    src = tmp_path / "roads.geojson"
    _lonlat_geojson(src, gap_m)
    out = tmp_path / "roads.gpkg"
    res = _run("convert", src, out, "--snap", "0.005")
    assert res.exit_code == 0, res.output
    m = apygis.read(out)
    assert m.crs.to_epsg() == 4326
    (lay,) = m.layers.values()
    chains = lay.chains()
    if joined:  # merged end to start into one line of three points
        assert len(chains) == 1
        assert len(lay.line_points) == 3
    else:  # two lines, nothing moved
        assert len(chains) == 2
        assert len(lay.line_points) == 4
        xs = sorted(lay.line_points["x"].tolist())
        assert xs[2] - xs[1] == pytest.approx(gap_m / 76_056.0, rel=1e-6)
