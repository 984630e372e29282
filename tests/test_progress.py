"""Every ``progress=`` of apygis is the one callback of :mod:`apygis.progress`.

Each public function taking ``progress`` is called on the sample sheet with a
recording callback; its calls must be ``(done, total)`` ints with
``0 <= done <= total``, one ``total`` per operation, ``done`` never going
down, and ``done == total`` at the end. A new public function with a
``progress`` parameter fails :func:`test_every_progress_function_is_checked`
until it is added here.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import apygis
from apygis.formats import Driver, get_driver
from apygis.progress import STEPS, Progress, fraction, phase

# driver name -> the target of a write of the sample (as tests/formats/test_write_safety.py)
TARGETS = {
    "apy": "M",
    "ascii": "M.apa",
    "dxf": "M.dxf",
    "e00": "M.e00",
    "generate": "M.gen",
    "gpkg": "M.gpkg",
    "shp": "out",
    "geojson": "out",
    "fgb": "out",
    "patb": "M.patb",  # write only: a densification map (tests/formats/test_patb.py)
    "bluh": "M.bluh",
}

# public functions with a progress parameter that are not driver readers or writers,
# each exercised by a test below
OTHERS = {
    "apygis.formats.batch.convert_file",
    "apygis.formats.batch.convert_many",
    "apygis.formats.dxf.write.encode",
    "apygis.plot.drawing.build_drawing",
    "apygis.plot.labels.place_labels",
    "apygis.plot._mpl.drawing_figure",
    "apygis.plot.pdf.drawing_pdf",
    "apygis.plot.pdf.text_pages_pdf",
    "apygis.plot.raster.drawing_png",
    "apygis.plot.raster.drawing_rgba",
    "apygis.plot.raster.drawing_tiff",
    "apygis.aerotri.synth.synth_block",
    "apygis.aerotri.project.init_block",
    "apygis.aerotri.pyramid.build_pyramid",
    "apygis.aerotri.match.match_block",
    "apygis.aerotri.gcp.measure",
    "apygis.aerotri.adjust.adjust_block",
    "apygis.aerotri.sketch.sketch_points",
    "apygis.orient.bundle.adjust",
    "apygis.orient.bundle.robust_adjust",
}
# called by the gpkg, shp, geojson and fgb drivers' readers and writers (closures)
OTHERS |= {"apygis.formats.ogr.read", "apygis.formats.ogr.write"}
# the helpers of apygis.progress take a callback to wrap, they do not report
HELPERS = {"apygis.progress.phase"}


class Recorder:
    """A progress callback that keeps its calls."""

    def __init__(self):
        self.calls: list[tuple[int, int]] = []

    def __call__(self, done: int, total: int, /) -> None:
        self.calls.append((done, total))


def check_calls(calls, what=""):
    """The conventions of apygis.progress, for the calls of one operation."""
    assert calls, f"{what}: no progress reported"
    for done, total in calls:
        assert type(done) is int, f"{what}: done {done!r} is not an int"
        assert type(total) is int, f"{what}: total {total!r} is not an int"
        assert 0 <= done <= total, f"{what}: {done} of {total}"
    assert len({t for _, t in calls}) == 1, f"{what}: total changed: {calls}"
    dones = [d for d, _ in calls]
    assert dones == sorted(dones), f"{what}: done went down: {calls}"
    assert calls[-1][0] == calls[-1][1], f"{what}: the last call is not done: {calls}"


def _public_progress_functions() -> set[str]:
    found = set()
    for info in pkgutil.walk_packages(apygis.__path__, "apygis."):
        mod = importlib.import_module(info.name)
        for name, obj in vars(mod).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != mod.__name__:
                continue
            funcs = []
            if inspect.isfunction(obj):
                funcs = [(name, obj)]
            elif inspect.isclass(obj):
                funcs = [
                    (f"{name}.{n}", f)
                    for n, f in vars(obj).items()
                    if inspect.isfunction(f) and not n.startswith("_")
                ]
            for qual, f in funcs:
                if "progress" in inspect.signature(f).parameters:
                    found.add(f"{mod.__name__}.{qual}")
    return found


def _qualname(f) -> str:
    f = getattr(f, "func", f)  # functools.partial (the OGR drivers)
    return f"{f.__module__}.{f.__qualname__}"


def _driver_functions() -> set[str]:
    out = set()
    for name in TARGETS:
        drv = get_driver(name)
        out.update(_qualname(f) for f in (drv.reader, drv.writer) if f is not None)
    return out


def test_every_progress_function_is_checked():
    checked = _driver_functions() | OTHERS | HELPERS
    unchecked = sorted(_public_progress_functions() - checked)
    assert not unchecked, (
        "public functions taking progress= that tests/test_progress.py does not call: "
        + ", ".join(unchecked)
    )
    assert set(TARGETS) == set(apygis.drivers()), "a driver is not checked"


def test_every_progress_function_documents_the_signature():
    """A function's own docstring names ``(done, total)``, or the contract it follows does."""
    contract = (Driver.__doc__ or "") + (apygis.read.__doc__ or "") + (apygis.write.__doc__ or "")
    assert "apygis.progress" in contract, "the Driver contract does not name apygis.progress"
    for qual in sorted(OTHERS - _driver_functions()):
        mod, name = qual.rsplit(".", 1)
        doc = getattr(importlib.import_module(mod), name).__doc__ or ""
        assert "progress(done, total)" in doc or "Progress" in doc, f"{qual}: not documented"


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_driver_progress(name, sample_map, tmp_path):
    target = tmp_path / TARGETS[name]
    rec = Recorder()
    if "r" not in get_driver(name).modes:  # the bundle file drivers take a densification map
        from tests.formats.test_patb import densification_map

        apygis.write(densification_map(), target, driver=name, progress=rec)
        check_calls(rec.calls, f"{name} write")
        return
    apygis.write(sample_map, target, driver=name, progress=rec)
    check_calls(rec.calls, f"{name} write")
    rec = Recorder()
    apygis.read(target, driver=name, progress=rec)
    check_calls(rec.calls, f"{name} read")


def test_dxf_encode_progress(sample_map):
    from apygis.formats.dxf import encode

    rec = Recorder()
    encode(sample_map, progress=rec)
    check_calls(rec.calls, "dxf.encode")


def test_build_drawing_progress(sample_map):
    from apygis.plot.drawing import build_drawing

    rec = Recorder()
    build_drawing(sample_map, progress=rec)
    check_calls(rec.calls, "build_drawing")
    assert rec.calls[-1] == (STEPS, STEPS)
    rec = Recorder()
    build_drawing(apygis.MapFile("E", scale=1000), progress=rec)
    check_calls(rec.calls, "build_drawing (empty)")


def test_plot_output_progress(sample_map):
    """Label placement, the figure and every rendering report as they go."""
    import numpy as np

    from apygis.plot._mpl import drawing_figure
    from apygis.plot.drawing import build_drawing
    from apygis.plot.labels import LabelRequest, place_labels
    from apygis.plot.pdf import drawing_pdf, text_pages_pdf
    from apygis.plot.raster import drawing_png, drawing_rgba, drawing_tiff

    d = build_drawing(sample_map)
    for name, call in [
        ("drawing_pdf", lambda p: drawing_pdf(d, progress=p)),
        ("drawing_png", lambda p: drawing_png(d, dpi=30, progress=p)),
        ("drawing_rgba", lambda p: drawing_rgba(d, dpi=30, progress=p)),
        ("drawing_tiff", lambda p: drawing_tiff(d, dpi=30, progress=p)),
        ("text_pages_pdf", lambda p: text_pages_pdf("a\n" * 150, progress=p)),
    ]:
        rec = Recorder()
        call(rec)
        check_calls(rec.calls, name)
        assert len(rec.calls) > 2, name
    rec = Recorder()
    fig = drawing_figure(d, progress=rec)
    assert rec.calls == []  # reported while the figure is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    check_calls(rec.calls, "drawing_figure")
    rec = Recorder()
    reqs = [LabelRequest("A", 1.0, 1.0, 2.0, 1.4, 0.0, "point", 1.0)]
    place_labels(reqs, [], np.zeros((0, 4)), (0, 0, 10, 10), progress=rec)
    check_calls(rec.calls, "place_labels")
    rec = Recorder()
    place_labels([], [], np.zeros((0, 4)), (0, 0, 10, 10), progress=rec)
    assert rec.calls == [(0, 0)]


def test_convert_file_progress(sample_dir, tmp_path):
    from apygis.formats.batch import convert_file

    rec = Recorder()
    res = convert_file(str(sample_dir / "ZH1091"), str(tmp_path / "x.dxf"), progress=rec)
    assert res.ok, res.error
    check_calls(rec.calls, "convert_file")
    assert rec.calls[-1] == (STEPS, STEPS)


def test_convert_many_progress(sample_dir, tmp_path):
    from apygis.formats.batch import convert_many

    rec = Recorder()
    srcs = [str(sample_dir / "ZH1091"), str(tmp_path / "missing.apa")]
    results = convert_many(srcs, tmp_path / "o", "ascii", progress=rec)
    assert [r.ok for r in results] == [True, False]
    check_calls(rec.calls, "convert_many")
    assert rec.calls == [(1, 2), (2, 2)]


def test_the_protocol_and_helpers():
    rec = Recorder()
    assert isinstance(rec, Progress)
    assert phase(None, 0, 2) is None
    first, second = phase(rec, 0, 2), phase(rec, 1, 2)
    first(0, 3)
    first(3, 3)
    first(1, 3)  # a step going back does not move the whole back
    second(0, 0)
    check_calls(rec.calls, "phase")
    assert rec.calls == [(0, STEPS), (500, STEPS), (500, STEPS), (STEPS, STEPS)]
    assert fraction(5, 4) == 1.0
    with pytest.raises(ValueError, match="step 2 of 2"):
        phase(rec, 2, 2)


def test_aerotri_progress(tmp_path):
    """A two-image synthetic block through synth, init, a pyramid and match."""
    from apygis.aerotri.adjust import adjust_block
    from apygis.aerotri.block import Block
    from apygis.aerotri.gcp import measure, read_measurements
    from apygis.aerotri.match import MatchOptions, match_block
    from apygis.aerotri.project import init_block
    from apygis.aerotri.pyramid import build_pyramid
    from apygis.aerotri.sketch import sketch_points
    from apygis.aerotri.synth import SynthSpec, synth_block

    folder = tmp_path / "b"
    rec = Recorder()
    synth_block(folder, SynthSpec(strips=1, images_per_strip=2, size_px=500, seed=1), progress=rec)
    check_calls(rec.calls, "synth_block")
    rec = Recorder()
    init_block(
        tmp_path / "b.block",
        camera=folder / "camera.toml",
        images=folder / "images.csv",
        control=folder / "control.csv",
        progress=rec,
    )
    check_calls(rec.calls, "init_block")
    image = next(folder.glob("img_*.tif"))
    for what in ("build_pyramid", "build_pyramid (current)"):
        rec = Recorder()
        build_pyramid(image, tmp_path / "p.tif", progress=rec)
        check_calls(rec.calls, what)
    assert rec.calls == [(0, 0)]  # the pyramid is current: nothing to do
    rec = Recorder()
    with Block.open(tmp_path / "b.block") as b:
        match_block(b, MatchOptions(scheduler="sync"), progress=rec)
        check_calls(rec.calls, "match_block")
        assert rec.calls[-1] == (STEPS, STEPS)
        rec = Recorder()
        measure(b, read_measurements(folder / "gcp.csv"), progress=rec)
        check_calls(rec.calls, "gcp.measure")
        rec = Recorder()
        adjust_block(b, progress=rec)
        check_calls(rec.calls, "adjust_block")
        rec = Recorder()
        sketch_points(b, tmp_path / "s.pdf", progress=rec)
        check_calls(rec.calls, "sketch_points")


def test_bundle_progress():
    from apygis.aerotri.simulate import simulate_block
    from apygis.orient.bundle import adjust, robust_adjust

    pb = simulate_block(2, 4, points_per_image=80, seed=2).problem
    for f in (adjust, robust_adjust):
        rec = Recorder()
        f(pb, progress=rec)
        check_calls(rec.calls, f.__name__)
