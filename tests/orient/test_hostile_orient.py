"""Issue 9: hostile input to the orientation readers, the CLI and the real-time loop.

Each test reproduces a reported input and requires an ApygisError with a
clear message (naming the file and the place) within 5 seconds; before the
fixes these raised RecursionError, ValueError, OverflowError,
ZeroDivisionError or IsADirectoryError, returned int64-minimum motor steps,
printed "RMSE 0.000" for an exact fit, or accepted a camera looking away
from its points.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from apygis.cli.orient import orient
from apygis.errors import ApygisError, FormatError, OrientationError
from apygis.orient.collinearity import (
    ExteriorOrientation,
    InteriorOrientation,
    depth,
    ground_to_photo,
)
from apygis.orient.io import Orientation, dumps, load_orientation, loads
from apygis.orient.photo import approximate_orientation, orient_photo
from apygis.orient.readers import (
    read_control,
    read_map_measurements,
    read_photo_file,
    read_photo_measurements,
)
from apygis.orient.realtime import (
    MAX_MOTOR_STEPS,
    MarkPositionError,
    MotorCalibration,
    RealtimeLoop,
)
from apygis.orient.relative import relative_orientation
from apygis.orient.resection import resect
from apygis.orient.transforms import MirroredTransformWarning, fit_map_transform

from . import synth

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "orient"
CONTROL = SAMPLES / "ZH1091-control.txt"
MAP = SAMPLES / "ZH1091-map.txt"
PHOTOS = SAMPLES / "ZH1091-photos.txt"
PMEAS = SAMPLES / "ZH1091-photo-measurements.txt"
TRUTH = SAMPLES / "ZH1091-truth.orientation.json"

READERS = {
    "control": read_control,
    "map": read_map_measurements,
    "photos": read_photo_file,
    "photo-measurements": read_photo_measurements,
    "orientation": load_orientation,
}


@contextlib.contextmanager
def _within(seconds: float = 5.0):
    t0 = time.perf_counter()
    yield
    assert time.perf_counter() - t0 < seconds, f"took more than {seconds} s"


def _refused(reader, path, match, exc=FormatError):
    with _within(), pytest.raises(exc, match=match) as ei:
        reader(path)
    assert str(path) in str(ei.value)
    return ei.value


def _truth_doc() -> dict:
    d = json.loads(TRUTH.read_text())
    d["motors"] = [
        {
            "photo_id": "4711",
            "step_um": 2.0,
            "plate_rotation_rad": 0.01,
            "zero_x_steps": 0,
            "zero_y_steps": 0,
            "scale_ratio": 0.33,
        }
    ]
    d["height_correction"] = {
        "A": 0.1,
        "B": 0.2,
        "C": 0.0,
        "D": 0.3,
        "Xc": 2684000.0,
        "Yc": 1248000.0,
        "scale_m": 800.0,
    }
    return d


def test_truth_doc_is_valid():
    o = loads(json.dumps(_truth_doc()))
    assert o.motors[0].step_um == 2.0
    assert o.height_correction.scale_m == 800.0


# ---------------------------------------------------------------- 1. JSON


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[" * 100_000, "nested too deeply"),
        ('{"a":' * 5000 + "1" + "}" * 5000, "nested too deeply"),
        ("[" * 40 + "]" * 40, "nested too deeply"),  # parses, but deeper than 32
        (
            '{"format": "apygis-orientation", "version": ' + "1" * 5000 + "}",
            r"version: an integer of 5000 digits is out of range",
        ),
        ('{"format": "apygis-orientation", "version": 1, "map_id": NaN}', "map_id: NaN"),
        ('{"format": "apygis-orientation", "version": 1, "x": -Infinity}', "x: -Infinity"),
        ('{"format": "apygis-orientation", "version": 1, "x": 1e400}', r"x: the number 1e400"),
    ],
)
def test_json_hostile_documents(tmp_path, text, match):
    p = tmp_path / "o.json"
    p.write_text(text)
    _refused(load_orientation, p, match)


def _set(d, path, value):
    node = d
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value


HUGE = 10**400  # beyond a double and Python's int-str limit as text


@pytest.mark.parametrize(
    ("path", "value", "match"),
    [
        (("photos", 0, "focal_mm"), HUGE, r"photos\[0\]\.focal_mm: an integer of 401 digits"),
        (("photos", 0, "Xo"), 1e400, r"photos\[0\]\.Xo: the number 1e400 is out of range"),
        (("motors", 0, "zero_x_steps"), 10**30, r"motors\[0\].zero_x_steps: an integer of 31"),
        (("motors", 0, "zero_x_steps"), 10**15, r"motors\[0\]: 'zero_x_steps' must lie in"),
        (("motors", 0, "step_um"), 5e-324, r"motors\[0\]: 'step_um' must lie in"),
        (("motors", 0, "step_um"), 0, r"motors\[0\]: 'step_um' must lie in"),
        (("height_correction", "scale_m"), 5e-324, "height_correction: 'scale_m' must lie in"),
        (("height_correction", "scale_m"), 0.0, "height_correction: 'scale_m' must lie in"),
        (("photos", 0, "sx_mm_per_m"), 0.0, r"photos\[0\]: 'sx_mm_per_m' must be non-zero"),
        (("photos", 0, "sy_mm_per_m"), 1e300, r"photos\[0\]: 'sy_mm_per_m' must be non-zero"),
        (("photos", 0, "focal_mm"), 1e-300, r"photos\[0\]: 'focal_mm' must lie in"),
        (("map", "a"), 1e200, "map: 'a' must lie in"),
        (("quality",), 5, "'quality' must be an object"),
        (("quality",), [], "'quality' must be an object"),
    ],
)
def test_json_numbers_out_of_range(tmp_path, path, value, match):
    d = _truth_doc()
    _set(d, path, value)
    p = tmp_path / "o.json"
    text = json.dumps(d).replace("Infinity", "1e400")  # json.dumps writes inf as Infinity
    p.write_text(text)
    _refused(load_orientation, p, match)


def _fields():
    d = _truth_doc()
    for key in d["photos"][0]:
        yield ("photos", 0, key)
    for key in d["motors"][0]:
        yield ("motors", 0, key)
    for key in d["height_correction"]:
        yield ("height_correction", key)
    for key in d["map"]:
        yield ("map", key)
    for key in ("format", "version", "map_id", "map", "photos", "height_correction", "motors"):
        yield (key,)


WRONG = ["x", 1.5, True, None, [1], {"a": 1}, 7]


@pytest.mark.parametrize("path", list(_fields()), ids=lambda p: ".".join(map(str, p)))
def test_json_wrong_type_for_every_field(tmp_path, path):
    """Every field with every wrong JSON type: a FormatError naming the place, or valid."""
    p = tmp_path / "o.json"
    for value in WRONG:
        d = _truth_doc()
        _set(d, path, value)
        p.write_text(json.dumps(d))
        message = ""
        with _within():
            try:
                load_orientation(p)
            except FormatError as exc:
                message = str(exc)
        if message:
            assert str(p) in message
            where = path[0] if path[0] not in ("format", "version") else ""
            assert where in message, (path, value, message)


# ---------------------------------------------------------------- 1. text files


@pytest.mark.parametrize(
    ("reader", "text", "match"),
    [
        (read_control, "1 " + "9" * 5000 + " 2 3\n", "line 1: X must be a finite number"),
        (read_control, "1 1e400 2 3\n", "line 1: X must be a finite number"),
        (read_control, "1 1e300 2 3\n", r"line 1: X must lie in \[-1e\+08, 1e\+08\] m"),
        (read_control, "1 1_000 2 3\n", "line 1: X must be a number, got '1_000'"),
        (read_control, "1 Infinity 2 3\n", "line 1: X must be a finite number"),
        (read_map_measurements, "1 1e6 2\n", "line 1: x_mm must lie in"),
        (read_photo_measurements, "1 P 0.1 -1e300\n", "line 1: py_mm must lie in"),
        (read_photo_file, "P 153 frame sx=0\n", "line 1: sx must be non-zero"),
        (read_photo_file, "P 153 frame sy=1e-320\n", "line 1: sy must be non-zero"),
        (read_photo_file, "P 1e-300 frame\n", "line 1: FOCAL_MM must lie in"),
        (read_photo_file, "P 153 frame Zo~1e300\n", "line 1: Zo must lie in"),
        (read_photo_file, "P 153 frame kappa_gon~1e300\n", r"kappa_gon \(in radians\) must lie"),
        (read_photo_file, "P 153 frame x0_mm=1e9\n", "line 1: x0_mm must lie in"),
    ],
)
def test_text_numbers_refused(tmp_path, reader, text, match):
    p = tmp_path / "in.txt"
    p.write_text(text)
    _refused(reader, p, match)


def test_text_file_of_empty_lines_is_cheap(tmp_path):
    """Millions of empty lines: no list of all lines (memory), well under 5 s."""
    p = tmp_path / "c.txt"
    p.write_bytes(b"\n" * 5_000_000)
    with _within():
        assert read_control(p) == {}


def test_oversized_input_is_refused(tmp_path):
    p = tmp_path / "c.txt"
    with open(p, "wb") as f:
        f.truncate(17 * 2**20)  # sparse
    _refused(read_control, p, "larger than the 16777216 bytes a file may have")
    p = tmp_path / "o.json"
    with open(p, "wb") as f:
        f.truncate(5 * 2**20)
    _refused(load_orientation, p, "larger than the 4194304 bytes an orientation file may have")


# ---------------------------------------------------------------- 2. paths


def _bad_paths(tmp_path):
    loop = tmp_path / "loop.json"
    os.symlink(loop, loop)
    fifo = tmp_path / "fifo.txt"
    os.mkfifo(fifo)  # would block a plain open() forever
    return {
        "a directory": (tmp_path, "is a directory"),
        "a missing file": (tmp_path / "missing.txt", "no such"),
        "a symlink loop": (loop, "symbolic links"),
        "a FIFO": (fifo, "not a regular file"),
    }


@pytest.mark.parametrize("name", sorted(READERS))
def test_readers_name_bad_paths(tmp_path, name):
    for path, match in _bad_paths(tmp_path).values():
        _refused(READERS[name], path, match)


def _cli(*args):
    return CliRunner().invoke(orient, [str(a) for a in args])


def _one_line_error(r, path):
    assert r.exit_code == 1, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit)
    assert "Traceback" not in r.output
    lines = r.output.strip().splitlines()
    assert lines[-1].startswith("Error: "), r.output
    assert str(path) in lines[-1], r.output


@pytest.mark.parametrize(
    "args",
    [
        ("map", "{}", MAP),
        ("map", CONTROL, "{}"),
        ("map", CONTROL, MAP, "-o", "{}"),
        ("photos", "{}", CONTROL, PMEAS),
        ("photos", PHOTOS, "{}", PMEAS),
        ("photos", PHOTOS, CONTROL, "{}"),
        ("photos", PHOTOS, CONTROL, PMEAS, "-o", "{}"),
    ],
    ids=[
        "map-control",
        "map-measurements",
        "map-output",
        "photos-photofile",
        "photos-control",
        "photos-measurements",
        "photos-output",
    ],
)
def test_cli_every_file_argument(tmp_path, args):
    for what, (path, _match) in _bad_paths(tmp_path).items():
        if "-o" in args and what == "a missing file":
            continue  # a new output file is fine
        with _within():
            r = _cli(*(path if a == "{}" else a for a in args))
        _one_line_error(r, path)
        if "-o" in args:  # checked before any work is printed
            assert len(r.output.strip().splitlines()) == 1, r.output


# ---------------------------------------------------------------- 3. real-time loop


def _loop():
    left, right = synth.pair()
    ml = MotorCalibration("L", step_um=2.0, plate_rotation_rad=0.03, zero_x_steps=100)
    mr = MotorCalibration("R", step_um=2.5, plate_rotation_rad=-0.02)
    return RealtimeLoop(left, right, ml, mr)


BAD_MARKS = [
    ((math.nan, synth.YM, 500.0), "must be finite"),
    ((synth.XM, math.inf, 500.0), "must be finite"),
    ((synth.XM, synth.YM, -math.inf), "must be finite"),
    ((1e308, synth.YM, 500.0), "must be finite|not in front|beyond"),
    ((synth.XM, synth.YM, 1e308), "not in front of photo"),
    ((synth.XM, synth.YM, 5000.0), "not in front of photo L"),  # above the aircraft
]


@pytest.mark.parametrize(("mark", "match"), BAD_MARKS)
def test_loop_refuses_bad_marks(mark, match):
    loop = _loop()
    with _within(), pytest.raises(MarkPositionError, match=match):
        loop.update(*mark)
    good = synth.model_points(5, np.random.default_rng(3))
    batch = np.vstack([good, [mark], good])
    with _within(), pytest.raises(MarkPositionError, match=rf"mark position 5 .*({match})"):
        loop.update_many(batch)


def _offsets(po, mc, G):
    """Motor offsets ``n - zero`` of each point (Python ints: no overflow)."""
    nx, ny = MotorCalibration(mc.photo_id, mc.step_um, mc.plate_rotation_rad).steps(
        *po.parallax(G).T
    )
    return nx.astype(object), ny.astype(object)


@pytest.mark.parametrize("step_um", [2.0, 1e-6])
def test_loop_motor_range_edges(step_um):
    """Zero positions near the end of the motor range: update and update_many refuse
    exactly the points that would drive a motor beyond +-MAX_MOTOR_STEPS."""
    left, right = synth.pair()
    G = synth.model_points(60, np.random.default_rng(4))
    ox, _ = _offsets(left, MotorCalibration("L", step_um), G)
    zero = MAX_MOTOR_STEPS - int(np.median(ox.astype(float)))  # about half the points beyond
    ml = MotorCalibration("L", step_um=step_um, zero_x_steps=zero)
    mr = MotorCalibration("R", step_um=step_um, zero_y_steps=-MAX_MOTOR_STEPS)
    loop = RealtimeLoop(left, right, ml, mr)
    lx, ly = _offsets(left, ml, G)
    rx, ry = _offsets(right, mr, G)
    ok = [
        all(
            -MAX_MOTOR_STEPS <= z + o <= MAX_MOTOR_STEPS
            for z, o in zip((zero, 0, 0, -MAX_MOTOR_STEPS), n, strict=True)
        )
        for n in zip(lx, ly, rx, ry, strict=True)
    ]
    assert any(ok)
    assert not all(ok)
    for g, good in zip(G, ok, strict=True):
        if good:
            u = loop.update(*g)
            assert max(map(abs, u[8:])) <= MAX_MOTOR_STEPS
            assert loop.update_many([g]).steps.tolist() == [list(u[8:])]
        else:
            with pytest.raises(MarkPositionError, match=f"beyond \\+-{MAX_MOTOR_STEPS} steps"):
                loop.update(*g)
            with pytest.raises(MarkPositionError, match=r"mark position 0 .*beyond"):
                loop.update_many([g])
    with pytest.raises(MarkPositionError, match="beyond"):
        loop.update_many(G)
    with pytest.raises(OrientationError, match="within"):
        MotorCalibration("L", zero_x_steps=MAX_MOTOR_STEPS + 1)
    with pytest.raises(OrientationError, match="step_um must lie in"):
        MotorCalibration("L", step_um=5e-324)


def test_loop_refuses_non_numbers():
    loop = _loop()
    for bad in ("a", 10**400, np.zeros(2)):
        with pytest.raises(MarkPositionError, match="numbers"):
            loop.update(bad, 1.0, 2.0)
    with pytest.raises(MarkPositionError, match="numbers"):
        loop.update_many([["a", 1.0, 2.0]])


def test_loop_results_unchanged_for_good_marks():
    loop = _loop()
    G = synth.model_points(500, np.random.default_rng(5))
    b = loop.update_many(G)
    for i in range(0, 500, 50):
        u = loop.update(*G[i])
        assert (u.steps_left_x, u.steps_left_y, u.steps_right_x, u.steps_right_y) == tuple(
            b.steps[i]
        )
    assert loop.update_many(np.empty((0, 3))).steps.shape == (0, 4)


# ---------------------------------------------------------------- 4. no redundancy


CTRL4 = {
    "1": (2683000.0, 1247000.0),
    "2": (2684000.0, 1247000.0),
    "3": (2683000.0, 1248000.0),
    "4": (2684000.0, 1248000.0),
}


@pytest.mark.parametrize(
    ("model", "ids", "tab"),
    [
        ("affine", ["1", "2", "3"], [[100, 100], [300, 100.1], [100.2, 300]]),
        ("bilinear", ["1", "2", "3", "4"], [[100, 100], [300, 100.1], [100.2, 300], [301, 300]]),
        ("conformal", ["1", "1", "2", "2"], [[100, 100], [100.01, 100], [300, 100], [300, 100.02]]),
    ],
)
def test_map_without_redundancy_is_not_checked(model, ids, tab):
    fit = fit_map_transform(ids, np.array(tab, dtype=float), CTRL4, model)
    assert fit.redundancy == 0
    assert not fit.checked
    assert math.isnan(fit.rmse)
    assert math.isnan(fit.sigma0)
    s = json.loads(json.dumps(fit.summary(), allow_nan=True).replace("NaN", "null"))
    assert s["redundancy"] == 0
    assert s["rmse_m"] is None
    assert s["sigma0_m"] is None
    # one more point: checked again
    ctrl5 = {**CTRL4, "5": (2683500.0, 1247500.0)}
    more = fit_map_transform(
        [*ids, "5", "5"], np.array([*tab, [200, 200], [200, 200.01]], dtype=float), ctrl5, model
    )
    assert more.redundancy > 0
    assert math.isfinite(more.rmse)


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_cli_map_without_redundancy(tmp_path):
    c = _write(tmp_path, "c.txt", "".join(f"{k} {X} {Y} -\n" for k, (X, Y) in CTRL4.items()))
    m = _write(tmp_path, "m.txt", "1 100 100\n2 300 100.1\n3 100.2 300\n")
    out = tmp_path / "o.json"
    r = _cli("map", c, m, "-o", out)
    assert r.exit_code == 0, r.output
    assert "no redundancy: the result is not checked" in r.output
    assert "RMSE in position" not in r.output
    q = load_orientation(out).quality["map"]
    assert q["redundancy"] == 0
    assert q["rmse_m"] is None
    assert q["sigma0_m"] is None


def _four_spot_photo(tmp_path):
    true = synth.pair()[0]
    rng = np.random.default_rng(1)
    G = synth.control_spots(8, rng)[:4]
    P = true.parallax(G) + rng.normal(0, 0.003, (4, 2))
    c = _write(
        tmp_path,
        "c.txt",
        "".join(f"{i} {X:.4f} {Y:.4f} {Z:.4f}\n" for i, (X, Y, Z) in enumerate(G)),
    )
    pm = _write(
        tmp_path, "pm.txt", "".join(f"{i} L {x:.6f} {y:.6f}\n" for i, (x, y) in enumerate(P))
    )
    e = true.exterior
    ph = _write(
        tmp_path,
        "ph.txt",
        f"L {true.interior.focal_mm} frame Xo~{e.Xo + 30} Yo~{e.Yo - 20} Zo~{e.Zo + 40} "
        "kappa_gon~200\n",
    )
    return G, P, true, ph, c, pm


def test_photo_without_redundancy_is_not_checked(tmp_path):
    G, P, true, *_ = _four_spot_photo(tmp_path)
    approx, _ = approximate_orientation(
        "L",
        true.interior,
        centre_xy=(true.exterior.Xo + 30, true.exterior.Yo - 20),
        mean_height=float(G[:, 2].mean()),
        scale_number=15000.0,
    )
    r = orient_photo(G, P, approx)
    assert len(r.free) == 8
    assert r.redundancy == 0
    assert not r.checked
    assert math.isnan(r.rmse_mm)
    assert math.isnan(r.rmse_ground_m)
    assert all(math.isnan(v) for v in r.std.values())


def test_cli_photo_without_redundancy(tmp_path):
    *_, ph, c, pm = _four_spot_photo(tmp_path)
    out = tmp_path / "o.json"
    r = _cli("photos", ph, c, pm, "-o", out)
    assert r.exit_code == 0, r.output
    assert "no redundancy: the result is not checked" in r.output
    assert "RMSE in position" not in r.output
    assert "(known)" not in r.output  # all eight were solved
    assert r.output.count("(solved, no sigma: not checked)") == 8
    q = load_orientation(out).quality["photos"]["L"]
    assert q["redundancy"] == 0
    assert q["rmse_mm"] is None
    assert q["sigma0_mm"] is None
    assert set(q["std"]) == {"Xo", "Yo", "Zo", "omega", "phi", "kappa", "sx", "sy"}
    assert all(v is None for v in q["std"].values())


def test_cli_known_parameters_still_labelled_known():
    r = _cli("photos", PHOTOS, CONTROL, PMEAS)
    assert r.exit_code == 0, r.output
    assert "(known)" in r.output
    assert "not checked" not in r.output


# ---------------------------------------------------------------- 5. behind the camera


def test_resection_refuses_swapped_photo_coordinates():
    io = InteriorOrientation(153.0)
    eo = ExteriorOrientation(1000.0, 2000.0, 2800.0, 0.01, -0.02, 0.3)
    rng = np.random.default_rng(0)
    G = np.column_stack(
        [rng.uniform(0, 2000, 6), rng.uniform(1000, 3000, 6), rng.uniform(400, 600, 6)]
    )
    p = ground_to_photo(G, eo, io)
    r = resect(G, p, io)
    assert np.all(depth(G, r.exterior, io) < 0)
    with _within(), pytest.raises(OrientationError, match="6 of 6 control points lie behind"):
        resect(G, p[:, ::-1], io)


def test_relative_orientation_refuses_swapped_photo_coordinates():
    io = InteriorOrientation(153.0)
    rng = np.random.default_rng(0)
    rng.uniform(size=18)  # the state of the documented example
    L = ExteriorOrientation(0.0, 0.0, 0.0)
    R = ExteriorOrientation(1.0, 0.02, -0.01, 0.01, -0.02, 0.03)
    M = np.column_stack(
        [rng.uniform(-0.3, 1.3, 9), rng.uniform(-1, 1, 9), rng.uniform(-1.8, -1.6, 9)]
    )
    p1, p2 = ground_to_photo(M, L, io), ground_to_photo(M, R, io)
    ro = relative_orientation(p1, p2, io)
    np.testing.assert_allclose(ro.parameters, [0.02, -0.01, 0.01, -0.02, 0.03], atol=1e-9)
    with _within(), pytest.raises(OrientationError, match=r"\d+ of 9 behind the left"):
        relative_orientation(p1[:, ::-1], p2[:, ::-1], io)
    # a twisted pair (right camera turned by half a turn about the base)
    with pytest.raises(OrientationError, match="behind"):
        relative_orientation(p1, p2, io, approx=(0.0, 0.0, math.pi, 0.0, 0.0))


# ---------------------------------------------------------------- 6. mirrored map


def test_mirrored_map_transform_warns():
    ids = ["1", "2", "3", "4"]
    tab = np.array([[100, 100], [300, 100.1], [100.2, 300], [301, 300]], dtype=float)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit = fit_map_transform(ids, tab, CTRL4, "affine")
    assert not fit.mirrored
    for model in ("affine", "bilinear", "conformal"):
        ids2 = ids + ids
        tab2 = np.vstack([tab, tab + 0.01])[:, ::-1]  # x and y swapped
        with pytest.warns(MirroredTransformWarning, match="mirrors the tablet"):
            fit = fit_map_transform(ids2, tab2, CTRL4, model)
        assert fit.mirrored
        assert fit.summary()["mirrored"] is True


def test_cli_mirrored_map_warns_on_stderr(tmp_path):
    c = _write(tmp_path, "c.txt", "".join(f"{k} {X} {Y} -\n" for k, (X, Y) in CTRL4.items()))
    m = _write(tmp_path, "m.txt", "1 100 100\n2 100.1 300\n3 300 100.2\n4 300 301\n")
    r = CliRunner().invoke(orient, ["map", str(c), str(m)])
    assert r.exit_code == 0, r.output
    err = r.stderr.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("warning: the affine map transform mirrors the tablet")


def test_singular_map_transform_refused():
    same = {k: (2683000.0, 1247000.0) for k in CTRL4}
    tab = np.array([[100, 100], [300, 100.1], [100.2, 300], [301, 300]], dtype=float)
    with pytest.raises(ApygisError, match="same ground position"):
        fit_map_transform(list(CTRL4), tab, same, "affine")
    line = {k: (2683000.0 + i, 1247000.0 + i) for i, k in enumerate(CTRL4)}
    with pytest.raises(ApygisError, match="collinear"):
        fit_map_transform(list(CTRL4), tab, line, "affine")


def test_library_refuses_huge_python_ints():
    """Integers beyond a double reach no float() or math.isfinite unguarded."""
    from apygis.orient.readers import control_for

    huge = {**CTRL4, "1": (10**400, 1247000.0)}
    tab = np.array([[100, 100], [300, 100.1], [100.2, 300], [301, 300]], dtype=float)
    with pytest.raises(ApygisError, match="finite numbers"):
        fit_map_transform(list(CTRL4), tab, huge, "affine")
    with pytest.raises(ApygisError, match="three numbers"):
        control_for(["1"], {"1": (1.0, 2.0, 10**400)})
    with pytest.raises(ApygisError, match="huge integer"):
        ExteriorOrientation(10**400, 0.0, 0.0)
    d = _truth_doc()
    d["photos"][0]["Zo"] = 10**400
    with pytest.raises(FormatError, match="'Zo' must be a number, got a huge integer"):
        Orientation.from_dict(d)


def test_dumps_round_trip_of_hostile_free_document():
    o = loads(json.dumps(_truth_doc()))
    assert loads(dumps(o)).motors == o.motors
