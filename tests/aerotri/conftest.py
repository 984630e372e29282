"""A tiny synthetic film block, rendered once per test session (2 strips x 3 images)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def tiny_block_dir(tmp_path_factory):
    from apygis.aerotri.synth import SynthSpec, synth_block

    d = tmp_path_factory.mktemp("tiny") / "tiny"
    synth_block(d, SynthSpec(strips=2, images_per_strip=3, size_px=900, seed=3))
    return d


@pytest.fixture(scope="session")
def matched_tiny(tiny_block_dir, tmp_path_factory):
    """The tiny block initialised and matched (tie points, no control measured yet)."""
    from apygis.aerotri.block import Block
    from apygis.aerotri.match import MatchOptions, match_block
    from apygis.aerotri.project import init_block, plan

    d = tiny_block_dir
    blk = tmp_path_factory.mktemp("matched") / "tiny.block"
    init_block(blk, camera=d / "camera.toml", images=d / "images.csv", control=d / "control.csv")
    with Block.open(blk) as b:
        plan(b)
        match_block(b, MatchOptions(scheduler="sync"))
    return blk


@pytest.fixture
def tiny_copy(matched_tiny, tmp_path):
    """A private copy of the matched tiny block (its pyramids shared, read only)."""
    import shutil

    blk = tmp_path / "tiny.block"
    shutil.copy(matched_tiny, blk)
    (tmp_path / "tiny.block.pyramids").symlink_to(matched_tiny.with_name("tiny.block.pyramids"))
    return blk
