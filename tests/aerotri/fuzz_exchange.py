"""The block exchange readers, for tests/test_fuzz.py: one entry per kind of file.

``READERS[name] = (read, seed, write_back)``: ``read(path)`` reads one file of the kind
(its result is a block or the parsed records), ``seed(tmp_path) -> (bytes, file name)``
makes a valid file of it from a small simulated block, and ``write_back(result, folder)``
(or None) writes what was read with the format's writer, which may refuse it (an
ApygisError) but not crash. The corpus of each is ``tests/fuzz_corpus/<name>/``.
"""

from __future__ import annotations

import functools
from pathlib import Path

from apygis.aerotri.exchange import colmap, micmac, odm
from apygis.aerotri.exchange.bluh import read_bluh, write_bluh
from apygis.aerotri.exchange.patb import read_patb, write_patb
from tests.aerotri.exchange_blocks import sim_block


@functools.cache
def _block():
    return sim_block(2, 3, points_per_image=20, seed=5)


def _seed(write, file_name: str, **kw):
    def seed(tmp_path: Path):
        folder = tmp_path / f"seed-{write.__name__}"
        folder.mkdir(exist_ok=True)
        write(_block(), folder / "seed", **kw)
        return (folder / file_name).read_bytes(), file_name

    return seed


def _seed_colmap(file_name: str):
    def seed(tmp_path: Path):
        folder = tmp_path / "seed-colmap"
        colmap.write_colmap(_block(), folder)
        return (folder / file_name).read_bytes(), f"seed-{file_name}"

    return seed


def _seed_odm(tmp_path: Path):
    odm.write_odm(_block(), tmp_path / "gcp_list.txt")
    return (tmp_path / "gcp_list.txt").read_bytes(), "seed-gcp_list.txt"


def _back(write, **kw):
    def back(block, folder: Path):
        folder.mkdir(exist_ok=True)
        write(block, folder / "back", **kw)

    return back


def _back_colmap(block, folder: Path):
    colmap.write_colmap(block, folder / "back")


READERS = {
    "patb-im": (read_patb, _seed(write_patb, "seed.im"), _back(write_patb)),
    "patb-con": (read_patb, _seed(write_patb, "seed.con"), _back(write_patb)),
    "patb-ori": (read_patb, _seed(write_patb, "seed.ori"), _back(write_patb)),
    "bluh-pho": (read_bluh, _seed(write_bluh, "seed.pho"), _back(write_bluh)),
    "bluh-ctl": (read_bluh, _seed(write_bluh, "seed.ctl"), _back(write_bluh)),
    "colmap-cameras": (colmap.read_cameras, _seed_colmap("cameras.txt"), None),
    "colmap-images": (colmap.read_images, _seed_colmap("images.txt"), None),
    "colmap-points3d": (colmap.read_points3d, _seed_colmap("points3D.txt"), None),
    "odm": (odm.read_odm, _seed_odm, _back(odm.write_odm)),
    "micmac-3d": (
        micmac.read_micmac,
        _seed(micmac.write_micmac, "seed_3d_gcp.xml"),
        _back(micmac.write_micmac),
    ),
    "micmac-2d": (
        micmac.read_micmac,
        _seed(micmac.write_micmac, "seed_2d_gcp.xml"),
        _back(micmac.write_micmac),
    ),
}
