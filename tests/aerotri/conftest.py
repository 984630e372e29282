"""A tiny synthetic film block, rendered once per test session (2 strips x 3 images)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def tiny_block_dir(tmp_path_factory):
    from apygis.aerotri.synth import SynthSpec, synth_block

    d = tmp_path_factory.mktemp("tiny") / "tiny"
    synth_block(d, SynthSpec(strips=2, images_per_strip=3, size_px=900, seed=3))
    return d
