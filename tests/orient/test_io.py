"""The orientation file: round trips, atomic writes, clear errors."""

from __future__ import annotations

import contextlib
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from apygis.errors import FormatError
from apygis.orient.height import HeightCorrection
from apygis.orient.io import Orientation, dumps, load_orientation, loads, save_orientation
from apygis.orient.realtime import MotorCalibration
from apygis.orient.transforms import AffineTransform, BilinearTransform, ConformalTransform

from . import synth


def _full():
    left, right = synth.pair()
    return Orientation(
        map_id="ZH1091",
        map_transform=AffineTransform(4.9995, -0.0307, 2682701.3, 0.0320, 5.0075, 1246747.6),
        photos=(left, right),
        height_correction=HeightCorrection(0.1, -0.2, 0.01, 0.3, 2684200.0, 1247800.0, 700.0),
        motors=(MotorCalibration("L", 2.0, 0.01, 3, -4, 0.334), MotorCalibration("R", 2.5)),
        quality={"map": {"rmse_m": 0.3, "sigma0_m": float("nan")}},
    )


def test_round_trip(tmp_path):
    o = _full()
    p = save_orientation(o, tmp_path / "o.json")
    back = load_orientation(p)
    assert back.map_transform == o.map_transform
    assert back.photos == o.photos
    assert back.height_correction == o.height_correction
    assert back.motors == o.motors
    assert back.map_id == "ZH1091"
    assert back.quality["map"]["sigma0_m"] is None  # nan is written as null
    assert back.photo("R") == o.photo("R")
    assert back.motor("L") == o.motor("L")
    assert dumps(back) == dumps(Orientation.from_dict(json.loads(dumps(o))))
    assert [f.name for f in tmp_path.iterdir()] == ["o.json"]  # no temporary file left


@settings(max_examples=60, deadline=None)
@given(
    st.sampled_from([ConformalTransform, AffineTransform, BilinearTransform]),
    st.lists(st.floats(-1e7, 1e7, allow_nan=False), min_size=8, max_size=8),
)
def test_transform_round_trip_exact(cls, vals):
    n = len(cls.__dataclass_fields__)
    o = Orientation(map_transform=cls(*vals[:n]))
    assert loads(dumps(o)).map_transform == o.map_transform


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from([ConformalTransform, AffineTransform, BilinearTransform]),
    st.lists(st.floats(-1e7, 1e7, allow_nan=False), min_size=8, max_size=8),
    st.floats(-1e4, 1e4, allow_nan=False),
    st.floats(-1e4, 1e4, allow_nan=False),
)
def test_one_position_is_transformed_to_the_same_bits(cls, vals, x, y):
    """forward_xy (the real-time path, floats) is forward (arrays) to the last bit."""
    t = cls(*vals[: len(cls.__dataclass_fields__)])
    X, Y = t.forward([x, y])
    got = t.forward_xy(x, y)
    assert type(got[0]) is float
    assert got == (float(X), float(Y))


def test_empty_orientation_round_trip():
    o = loads(dumps(Orientation()))
    assert o.map_transform is None
    assert o.photos == ()
    assert o.height_correction is None


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.update(format="other"), "not an orientation file"),
        (lambda d: d.update(version=99), "unsupported version 99"),
        (lambda d: d["photos"][1].pop("focal_mm"), r"photos\[1\]: missing key 'focal_mm'"),
        (lambda d: d["photos"][0].update(Xo="abc"), r"photos\[0\]: 'Xo' must be a number"),
        (
            lambda d: d["photos"][0].update(focal_mm=-3.0),
            r"photos\[0\]: 'focal_mm' must lie in \[0.001, 100000\] mm, got -3.0",
        ),
        (lambda d: d["map"].update(model="projective"), "map: 'model' must be one of"),
        (lambda d: d["map"].pop("e"), "map: missing key 'e'"),
        (lambda d: d["motors"][0].update(zero_x_steps=1.5), r"motors\[0\]: 'zero_x_steps' must be"),
        (lambda d: d["height_correction"].pop("D"), "height_correction: missing key 'D'"),
        (lambda d: d["photos"].append(dict(d["photos"][0])), "appear twice"),
        (lambda d: d.update(photos={}), "'photos' must be a list"),
    ],
)
def test_bad_documents_name_the_key(tmp_path, mutate, match):
    d = json.loads(dumps(_full()))
    mutate(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(FormatError, match=match) as ei:
        load_orientation(p)
    assert str(p) in str(ei.value)


def test_bad_json_names_line(tmp_path):
    p = tmp_path / "broken.json"
    p.write_text('{\n  "format": "apygis-orientation",\n  "version": 1,\n  oops\n}\n')
    with pytest.raises(FormatError, match=r"broken.json: line 4 column 3: invalid JSON"):
        load_orientation(p)
    p.write_bytes(b'{"format": "\xff"}')
    with pytest.raises(FormatError, match="not UTF-8"):
        load_orientation(p)
    with pytest.raises(FormatError, match="JSON object"):
        loads("[1, 2]")


@settings(max_examples=100, deadline=None)
@given(st.text(max_size=200))
def test_fuzz_never_crashes(text):
    with contextlib.suppress(FormatError):
        loads(text)


_json = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-5, 5)
    | st.floats(allow_nan=False)
    | st.text(max_size=4),
    lambda children: (
        st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=4), children, max_size=3)
    ),
    max_leaves=6,
)


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_structured_fuzz_mutated_values(data):
    """Replace one value anywhere in a valid document: a FormatError or a valid Orientation."""
    d = json.loads(dumps(_full()))
    path = []
    node = d
    while isinstance(node, dict | list) and node:
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        k = data.draw(st.sampled_from(keys))
        path.append(k)
        if not data.draw(st.booleans()):
            break
        node = node[k]
    parent = d
    for k in path[:-1]:
        parent = parent[k]
    if path:
        parent[path[-1]] = data.draw(_json)
    with contextlib.suppress(FormatError):
        loads(json.dumps(d))
