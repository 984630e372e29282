"""CRS reprojection of whole maps (apygis.model.reproject)."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import CRS

import apygis
from apygis.errors import ApygisError
from apygis.model.reproject import CRSError, has_height, reproject
from tests.formats.strategies import random_rows


def _coords(m):
    return {
        (lay.ext, name): np.column_stack([t["x"], t["y"], t["z"]])
        for lay in m
        for name in ("symbols", "line_points", "texts")
        if len(t := lay.table(name))
    }


def test_known_point_bern():
    m = apygis.MapFile("BE", scale=5000, crs="EPSG:2056", notes="Bern")
    m.layer("c").add_symbol(2600000.0, 1200000.0, 550.0, code=1)
    w = reproject(m, "EPSG:4326")
    (row,) = w.layers["c"].symbols
    # the old observatory of Bern, origin of the Swiss projection: 7°26'22.5" E, 46°57'08.7" N
    assert row["x"] == pytest.approx(7.438632, abs=1e-6)
    assert row["y"] == pytest.approx(46.951083, abs=1e-6)
    assert row["z"] == 550.0  # 2-D to 2-D: heights unchanged
    assert w.crs_string() == "EPSG:4326"
    assert (w.id, w.scale, w.notes) == ("BE", 5000, "Bern")


def test_round_trip_lv95_wgs84_lv95(sample_map):
    before = sample_map.copy()
    wgs = reproject(sample_map, "EPSG:4326")
    assert sample_map == before  # the input is not changed
    back = reproject(wgs, CRS.from_epsg(2056))
    assert back.crs_string() == "EPSG:2056"
    a, b = _coords(sample_map), _coords(back)
    assert a.keys() == b.keys()
    for key in a:
        d = np.hypot(*(b[key][:, :2] - a[key][:, :2]).T)
        # PROJ's 2-D CH1903+ <-> WGS 84 Helmert takes heights 0 on each ellipsoid, so the
        # two directions are not exact inverses: 1.3 mm here (see the module docstring)
        assert d.max() < 0.0015
        np.testing.assert_array_equal(b[key][:, 2], a[key][:, 2])
    for ext, lay in sample_map.layers.items():
        got = back.layers[ext]
        for name in ("symbols", "line_points", "texts"):
            fields = [f for f in lay.table(name).dtype.names if f not in ("x", "y", "z")]
            for f in fields:
                np.testing.assert_array_equal(got.table(name)[f], lay.table(name)[f])
        assert got.counts() == lay.counts()
        assert got.branches() == lay.branches()


def test_three_dimensional_crs_transform_heights_and_invert_exactly(sample_map):
    lv95_3d = CRS.from_epsg(2056).to_3d()
    assert has_height(lv95_3d)
    assert has_height("EPSG:4979")
    assert not has_height("EPSG:4326")
    m = sample_map.copy()
    m.crs = lv95_3d
    w = reproject(m, "EPSG:4979")
    dz = w.layers["e"].symbols["z"] - m.layers["e"].symbols["z"]
    assert 45 < dz.mean() < 55  # ellipsoidal heights of WGS 84 lie ~50 m above Bessel's here
    back = reproject(w, lv95_3d)
    a, b = _coords(m), _coords(back)
    for key in a:
        np.testing.assert_allclose(b[key], a[key], atol=1e-6, rtol=0)


def test_vectorised_on_many_points():
    rng = np.random.default_rng(5)
    lay = apygis.Layer.from_arrays("r", line_points=random_rows(rng, 200_000))
    m = apygis.MapFile("BIG", crs="EPSG:2056")
    m.add_layer(lay)
    w = reproject(m, "EPSG:4326")
    lp = w.layers["r"].line_points
    assert ((lp["x"] > 7) & (lp["x"] < 9.5)).all()
    assert ((lp["y"] > 46) & (lp["y"] < 48)).all()


def test_errors():
    m = apygis.MapFile("NOCRS")
    m.layer("r").add_symbol(1.0, 2.0, 3.0, 0)
    with pytest.raises(CRSError, match="map NOCRS has no CRS") as info:
        reproject(m, "EPSG:4326")
    assert isinstance(info.value, ApygisError)
    assert isinstance(info.value, ValueError)
    m.crs = "EPSG:2056"
    with pytest.raises(CRSError, match="not a coordinate reference system"):
        reproject(m, "EPSG:nonsense")
    geo = apygis.MapFile("POLE", crs="EPSG:4326")
    geo.layer("c").add_symbol(7.0, 46.0, 0.0, 1)
    geo.layer("c").add_text(7.0, 95.0, 0.0, "beyond the pole")
    with pytest.raises(CRSError, match=r"layer c: text 1 at \(7.000, 95.000\) cannot be"):
        reproject(geo, "EPSG:3857")


def test_empty_map_and_empty_layers():
    m = apygis.MapFile("E", crs="EPSG:2056")
    assert reproject(m, "EPSG:4326").layers == {}
    m.layer("q")
    w = reproject(m, "EPSG:4326")
    assert list(w.layers) == ["q"]
    assert len(w.layers["q"]) == 0
