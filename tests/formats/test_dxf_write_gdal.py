"""DXF writing as other programs read it: GDAL (pyogrio's OGR DXF driver, what QGIS
shows) and ezdxf see the texts as written, and the layers have colours."""

from __future__ import annotations

import warnings

import pytest

import apygis
from apygis.formats.dxf.write import LAYER_COLOURS, escape_text, layer_colours
from apygis.model.map import MapFile

ezdxf = pytest.importorskip("ezdxf")
pyogrio = pytest.importorskip("pyogrio")

NON_LATIN = ["Zürich", "Łódź", "Ελλάδα", "Plzeň"]
CARETS = ["a^Jb", "x^ y", "^", "^I", "1^2"]
PERCENTS = ["50%%d", "%%c10", "%%p5", "a%%ub", "100%", "%%%", "5% %"]


def _write(tmp_path, texts, exts=("r",)):
    m = MapFile("T", scale=1000, crs="EPSG:2056")
    for ext in exts:
        lay = m.layer(ext)
        lay.add_symbol(2683000.0, 1247000.0, 400.0, 5)
    lay = m.layer(exts[0])
    for i, t in enumerate(texts):
        lay.add_text(2683000.0 + i, 1247000.0, 400.0, t)
    path = tmp_path / "t.dxf"
    apygis.write(m, path)
    return m, path


def _gdal_texts(path) -> list[str]:
    with warnings.catch_warnings():
        # GDAL (with iconv) warns that it cannot recode "CP65001", then keeps the
        # UTF-8 text as it is: the texts come out right (see docs/formats/dxf.md)
        warnings.simplefilter("ignore", RuntimeWarning)
        meta, _, _, fields = pyogrio.raw.read(path)
    names = list(meta["fields"])
    kinds = fields[names.index("SubClasses")]
    text = fields[names.index("Text")]
    return [t for k, t in zip(kinds, text, strict=True) if k == "AcDbEntity:AcDbText:AcDbText"]


def _ezdxf_texts(path) -> tuple[list[str], list[str]]:
    doc = ezdxf.readfile(path)
    ents = doc.modelspace().query("TEXT")
    return [e.dxf.text for e in ents], [e.plain_text() for e in ents]


def test_non_latin_texts_read_right_by_gdal_and_ezdxf(tmp_path):
    m, path = _write(tmp_path, NON_LATIN)
    assert b"$DWGCODEPAGE\n  3\nANSI_65001\n" in path.read_bytes()
    assert _gdal_texts(path) == NON_LATIN
    raw, plain = _ezdxf_texts(path)
    assert raw == plain == NON_LATIN
    from ezdxf import recover

    doc, auditor = recover.readfile(path)
    assert not auditor.has_errors
    assert not auditor.has_fixes
    assert [e.dxf.text for e in doc.modelspace().query("TEXT")] == NON_LATIN
    assert apygis.read(path) == m
    assert apygis.read(path, fast=False) == m
    (tmp_path / "a").mkdir()
    _, ascii_path = _write(tmp_path / "a", ["Kirchweg", "Dorfbach"])
    assert ascii_path.read_bytes().isascii()  # nothing to recode: the Latin code page
    assert b"$DWGCODEPAGE\n  3\nANSI_1252\n" in ascii_path.read_bytes()


def test_carets_escaped_for_gdal_and_ezdxf(tmp_path):
    m, path = _write(tmp_path, CARETS)
    assert _gdal_texts(path) == CARETS
    _, plain = _ezdxf_texts(path)
    # ezdxf drops a caret at the very end of a text (its "^ " as trailing space)
    assert plain == [t if not t.endswith("^") else t[:-1] for t in CARETS]
    assert apygis.read(path) == m
    assert apygis.read(path, fast=False) == m


def test_percent_codes_escaped_as_autocad_does(tmp_path):
    m, path = _write(tmp_path, PERCENTS)
    raw, plain = _ezdxf_texts(path)
    assert raw == [escape_text(t) for t in PERCENTS]
    assert plain == PERCENTS  # ezdxf follows AutoCAD: "%%%" is a literal "%"
    # GDAL knows %%c, %%d, %%p, %%u, ... but not "%%%": texts without "%%" are exact
    gdal = _gdal_texts(path)
    assert [g for g, t in zip(gdal, PERCENTS, strict=True) if "%%" not in t] == ["100%", "5% %"]
    assert apygis.read(path) == m
    assert apygis.read(path, fast=False) == m


def test_escape_text():
    assert escape_text("Zürich") == "Zürich"
    assert escape_text("a^b") == "a^ b"
    assert escape_text("50%") == "50%"
    assert escape_text("%%d") == "%%%%%%d"


def test_layers_have_colours(tmp_path):
    _, path = _write(tmp_path, ["a"], exts=("c", "e", "h", "r", "x"))
    doc = ezdxf.readfile(path)
    colours = {lay.dxf.name: lay.dxf.color for lay in doc.layers if lay.dxf.name in "cehrx"}
    assert colours == layer_colours(["c", "e", "h", "r", "x"])
    assert colours["h"] == LAYER_COLOURS["h"] == 5
    assert len(set(colours.values())) == 5
    assert 7 not in colours.values()


def test_the_header_extent_is_the_records_extent(sample_map, tmp_path):
    import ezdxf
    import numpy as np

    path = tmp_path / "s.dxf"
    apygis.write(sample_map, path)
    doc = ezdxf.readfile(path)
    xyz = np.concatenate(
        [
            np.column_stack([t["x"], t["y"], t["z"]])
            for lay in sample_map.layers.values()
            for t in (lay.symbols, lay.line_points, lay.texts)
            if len(t)
        ]
    )
    assert tuple(doc.header["$EXTMIN"]) == tuple(xyz.min(axis=0))
    assert tuple(doc.header["$EXTMAX"]) == tuple(xyz.max(axis=0))
