"""The command line as ogr2ogr and fio users expect it: -o/--output, --to/--driver and
--src-driver, --src-crs, --layer, --layer-map, --co NAME=VALUE (declared per driver,
unknown refused), output paths, '-' for standard output, import options for foreign
data, info on a folder, batch conversion on a Dask cluster, error texts that name what
the user typed."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

import apygis
from apygis.cli import main
from tests.cli.test_conventions import ALL_COMMANDS
from tests.conftest import SAMPLES

pyogrio = pytest.importorskip("pyogrio")
shapely = pytest.importorskip("shapely")
ezdxf = pytest.importorskip("ezdxf")


def _run(*args, **kw):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False, **kw)


def _dxf(path, crs_units=False):
    doc = ezdxf.new("R2010")
    msp = doc.modelspace()
    doc.layers.add("ROADS")
    msp.add_line((2683000, 1247000, 0), (2683100, 1247000, 0), dxfattribs={"layer": "ROADS"})
    msp.add_point((2683050, 1247050, 0), dxfattribs={"layer": "TREES"})
    doc.saveas(path)
    return path


# --------------------------------------------------------------------------- output paths


def test_to_writes_the_file_named_not_a_folder(tmp_path):
    out = tmp_path / "x.gpkg"
    r = _run("convert", "--to", "gpkg", SAMPLES / "ZH1091", out)
    assert r.exit_code == 0, r.output
    assert out.is_file()
    assert apygis.read(out) == apygis.read(SAMPLES / "ZH1091")


def test_output_option_and_trailing_slash_make_a_folder(tmp_path):
    r = _run("convert", SAMPLES / "ZH1091.apa", "-o", f"{tmp_path}/new/", "--to", "dxf")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "new" / "ZH1091.dxf").is_file()


def test_one_input_into_an_existing_folder_keeps_its_format(tmp_path):
    r = _run("convert", SAMPLES / "ZH1091.apa", tmp_path)
    assert r.exit_code == 0, r.output
    assert apygis.read(tmp_path / "ZH1091.apa") == apygis.read(SAMPLES / "ZH1091.apa")


def test_dash_is_standard_output_where_the_format_streams(tmp_path):
    r = _run("convert", SAMPLES / "ZH1091", "--to", "dxf", "-o", "-")
    assert r.exit_code == 0, r.output
    data = r.stdout_bytes
    assert data.startswith(b"  0\nSECTION")
    (tmp_path / "s.dxf").write_bytes(data)
    assert apygis.read(tmp_path / "s.dxf") == apygis.read(SAMPLES / "ZH1091")
    r = _run("convert", SAMPLES / "ZH1091", "--to", "gpkg", "-")
    assert r.exit_code == 1
    assert "the gpkg driver does not write one file that can go to standard output" in r.output
    assert "ascii, dxf, e00" in r.output


# --------------------------------------------------------------------------- --co


def test_co_options_are_declared_per_driver(tmp_path):
    r = _run("convert", SAMPLES / "ZH1091", tmp_path / "a.dxf", "--co", "VERSION=R2013")
    assert r.exit_code == 0, r.output
    assert b"AC1027" in (tmp_path / "a.dxf").read_bytes()
    r = _run("convert", SAMPLES / "ZH1091", tmp_path / "b.dxf", "--co", "VERSION=R99")
    assert r.exit_code == 1
    assert "--co VERSION=R99: one of R2010, R2013, R2018 expected" in r.output
    r = _run("convert", SAMPLES / "ZH1091", tmp_path / "c.dxf", "--co", "FOO=1")
    assert r.exit_code == 1
    assert "--co FOO=1: the apy reader has no option 'foo'" in r.output
    assert "the dxf writer has no option 'foo' (it takes --co VERSION)" in r.output
    assert not (tmp_path / "c.dxf").exists()
    r = _run("convert", SAMPLES / "ZH1091", tmp_path / "v.gpkg", "--co", "version=1.4")
    assert r.exit_code == 0, r.output
    import sqlite3

    assert (
        sqlite3.connect(tmp_path / "v.gpkg").execute("PRAGMA user_version").fetchone()[0] == 10400
    )
    # a reading option through --co: the chord tolerance of a DXF's curves
    doc = ezdxf.new()
    doc.modelspace().add_circle((0, 0), 10)
    doc.saveas(tmp_path / "circle.dxf")
    coarse = _run("info", "--json", tmp_path / "circle.dxf", "--co", "CHORD_M=1")
    fine = _run("info", "--json", tmp_path / "circle.dxf", "--co", "chord_m=0.001")
    n = [json.loads(r.stdout)["totals"]["line_points"] for r in (coarse, fine)]
    assert n[0] < n[1]


def test_cut_texts_of_the_apy_writers(tmp_path):
    m = apygis.MapFile("LONG")
    m.layer("c").add_text(1.0, 2.0, 3.0, "Chilliwack General Hospital")
    apygis.write(m, tmp_path / "long.gpkg")
    r = _run("convert", tmp_path / "long.gpkg", tmp_path / "long.apa")
    assert r.exit_code == 1
    assert "text 1 ('Chilliwack General Hospital') has 27 characters; APY holds 24" in r.output
    assert "CUT_TEXTS=YES" in r.output
    assert not (tmp_path / "long.apa").exists()
    r = _run("convert", tmp_path / "long.gpkg", tmp_path / "long.apa", "--co", "CUT_TEXTS=YES")
    assert r.exit_code == 0, r.output
    texts = apygis.read(tmp_path / "long.apa").layers["c"].texts["text"].tolist()
    assert texts == ["Chilliwack General Hospi"]


# --------------------------------------------------------------------------- reading options


def test_src_crs_layer_and_layer_map_on_a_dxf(tmp_path):
    path = _dxf(tmp_path / "d.dxf")
    r = _run("info", "--json", path, "--src-crs", "EPSG:2056")
    d = json.loads(r.stdout)
    assert d["crs"] == "EPSG:2056"
    assert sorted(d["layers"]) == ["roa", "tre"]
    r = _run("info", "--json", path, "--layer", "TREES")
    assert sorted(json.loads(r.stdout)["layers"]) == ["tre"]
    r = _run("info", "--json", path, "--layer-map", "ROADS=r,TREES=-")
    assert sorted(json.loads(r.stdout)["layers"]) == ["r"]
    r = _run("info", path, "--layer-map", "NOSUCH=r")
    assert r.exit_code == 1
    assert (
        "layer map names 'NOSUCH', which the file does not have (its layers: 0, Defpoints, "
        "ROADS, TREES)" in r.output
    )
    r = _run("info", path, "--layer", "nope")
    assert r.exit_code == 1
    assert f"{path}: no layer 'nope' in the file" in r.output
    r = _run("convert", path, tmp_path / "d.gpkg", "--to-crs", "EPSG:4326")
    assert r.exit_code == 1
    assert "assign its CRS with --src-crs" in r.output
    assert "MapFile" not in r.output


def test_code_field_and_default_code_for_foreign_features(tmp_path):
    pts = shapely.to_wkb(shapely.points([(2600000.0, 1200000.0), (2600001.0, 1200001.0)]))
    path = tmp_path / "wells.gpkg"
    pyogrio.raw.write(
        path,
        pts,
        [np.array([2310, 27], np.int32), np.array([5, 6], np.int32)],
        ["objcode", "class"],
        layer="wells",
        driver="GPKG",
        geometry_type="Point",
        crs="EPSG:2056",
    )
    r = _run("info", "--json", path)  # no field 'code': imported points
    assert json.loads(r.stdout)["layers"]["wel"]["symbols"] == 2
    r = _run("info", path, "--code-field", "objcode")
    assert r.exit_code == 1
    assert "feature 1: objcode 2310 is not a code 0-99" in r.output
    r = _run("info", "--json", path, "--code-field", "objcode", "--default-code", "7")
    d = json.loads(r.stdout)
    assert d["read_warnings"][0]["kind"] == "recoded"
    out = tmp_path / "w.apa"
    r = _run("convert", path, out, "--code-field", "objcode", "--default-code", "7")
    assert r.exit_code == 0, r.output
    assert apygis.read(out).layers["wel"].symbols["code"].tolist() == [7, 27]
    r = _run("convert", path, tmp_path / "c.apa", "--code-field", "CLASS")
    assert apygis.read(tmp_path / "c.apa").layers["wel"].symbols["code"].tolist() == [5, 6]
    r = _run("info", SAMPLES / "ZH1091", "--code-field", "x")
    assert r.exit_code == 1
    assert "--code-field: the apy reader does not take it" in r.output


def test_text_field_for_foreign_points(tmp_path):
    pts = shapely.to_wkb(shapely.points([(2600000.0, 1200000.0)]))
    path = tmp_path / "names.gpkg"
    pyogrio.raw.write(
        path, pts, [np.array(["Chilliwack General Hospital"], object)], ["label"],
        layer="names", driver="GPKG", geometry_type="Point", crs="EPSG:2056",
    )  # fmt: skip
    r = _run("convert", path, tmp_path / "n.dxf", "--text-field", "label")
    assert r.exit_code == 0, r.output
    texts = apygis.read(tmp_path / "n.dxf").layers["nam"].texts["text"].tolist()
    assert texts == ["Chilliwack General Hospital"]  # whole: only APY's formats hold 24


# --------------------------------------------------------------------------- info on a folder


def test_info_on_a_folder_lists_its_maps(tmp_path):
    apygis.write(apygis.read(SAMPLES / "ZH1091"), tmp_path / "a.gpkg")
    apygis.write(apygis.read(SAMPLES / "ZH1091"), tmp_path / "ZH1091")  # APY layer files
    (tmp_path / "notes.txt").write_text("not a map\n")
    r = _run("info", tmp_path)
    assert r.exit_code == 0, r.output
    assert "2 maps, 1 other files" in r.output
    assert "not a map:" in r.output
    d = json.loads(_run("info", "--json", tmp_path).stdout)
    assert sorted(m["driver"] for m in d["maps"]) == ["apy", "gpkg"]
    assert [o["path"] for o in d["not_maps"]] == [str(tmp_path / "notes.txt")]


# --------------------------------------------------------------------------- batch on Dask


def test_batch_on_a_dask_cluster_by_its_address(sample_dir, tmp_path):
    from distributed import LocalCluster

    src = tmp_path / "in"
    src.mkdir()
    for i in range(3):
        m = apygis.read(sample_dir / "ZH1091")
        m.id = f"S{i}"
        apygis.write(m, src / f"sheet{i}.apa")
    (src / "junk.apa").write_text("APY ASCII 1\nMAP X\nLAYER r\nSYMBOLS 1\nbroken\nEND\n")
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        out = tmp_path / "out"
        r = _run(
            "convert",
            "--to",
            "gpkg",
            src / "*.apa",
            "-o",
            out,
            "--scheduler",
            cluster.scheduler_address,
        )
        assert r.exit_code == 1
        assert "3 converted, 1 failed" in r.output
        assert "FAILED" in r.output
        assert "junk.apa" in r.output
        for i in range(3):
            assert apygis.read(out / f"sheet{i}.gpkg").id == f"S{i}"
        r = _run("convert", "--to", "gpkg", src / "sheet0.apa", src / "sheet1.apa", "-o", out,
                 "--scheduler", cluster.scheduler_address)  # fmt: skip
        assert r.exit_code == 1  # nothing replaced without --overwrite
        assert "exists; use --overwrite" in r.output


# --------------------------------------------------------------------------- error texts


def test_error_texts_name_what_the_user_typed(tmp_path):
    (tmp_path / "empty.gpkg").write_bytes(b"")
    (tmp_path / "empty.apa").write_bytes(b"")
    outputs = [
        _run("info", tmp_path / "empty.gpkg").output,
        _run("info", tmp_path / "empty.apa").output,
        _run("info", SAMPLES / "ZH1091", "--src-driver", "nosuch").output,
        _run("convert", SAMPLES / "ZH1091", tmp_path / "x.dxf", "--driver", "nosuch").output,
        _run("convert", SAMPLES / "ZH1091", tmp_path / "y.gpkg", "--to-crs", "nonsense").output,
        _run("convert", SAMPLES / "ZH1091", tmp_path / "z.gpkg", "--snap", "-1").output,
    ]
    text = "\n".join(outputs)
    for bad in ("<DRIVER>", "np.str_", "driver=", "MapFile", "sagitta", "line 0", ".apygis-"):
        assert bad not in text, bad
    assert "GDAL does not recognise its content" in outputs[0]
    assert "the file is empty" in outputs[1]
    assert "--src-driver nosuch: no driver named 'nosuch'" in outputs[2]
    assert "--driver nosuch: no driver named 'nosuch'" in outputs[3]
    assert "--snap" in outputs[5]


# --------------------------------------------------------------------------- --help


def _help(path):
    return _run(*path, "--help").output


@pytest.mark.parametrize(
    "path", [("info",), ("validate",), ("convert",), ("plot",), ("printout",)], ids=" ".join
)
def test_commands_that_read_maps_share_the_input_options(path):
    text = _help(path)
    for opt in ("--src-driver", "--src-crs", "--layer", "--layer-map", "--snap", "--code-field",
                "--default-code", "--text-field", "--co NAME=VALUE"):  # fmt: skip
        assert opt in text, opt
    assert not re.search(r"^\s+--driver\b", text, re.M) or path == ("convert",)


def test_commands_with_an_output_file_take_o_output():
    for path in ALL_COMMANDS:
        text = _help(path)
        if re.search(r"--(output|tiepoints)\b", text):
            assert "-o, --output" in text, path
