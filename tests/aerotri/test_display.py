"""Tests of apygis.aerotri.display: the block display is written, as PNG and PDF."""

from __future__ import annotations

import io

import numpy as np
import pytest
from matplotlib.image import imread

from apygis.aerotri.display import block_display, count_class, nice_length
from apygis.aerotri.plan import Frame, PlanImage, gap_report, plan_block
from apygis.errors import FormatError

Z = 2030.0  # 1:10000 over terrain at 500 m: footprints 2300 m


def sample_plan():
    imgs, n = [], 1
    for s in range(3):
        for k in range(5):
            x = (4 - k) * 920.0 if s == 1 else k * 920.0
            imgs.append(PlanImage(n, s + 1, 10_000 + x, 50_000 + s * 1610.0, Z))
            n += 1
    imgs += [PlanImage(100 + k, 9, 11_840.0, 49_000.0 + k * 800.0, Z) for k in range(4)]
    return plan_block(imgs, Frame(153.0), 500.0)


CONTROL = [
    ("C1", 9_500.0, 49_000.0, "full"),
    ("C2", 14_000.0, 53_500.0, "planimetric"),
    ("H3", 14_000.0, 49_000.0, "height"),
    ("K1", 11_000.0, 51_000.0, "check"),
]


def test_block_display_png_and_pdf(tmp_path):
    plan = sample_plan()
    rng = np.random.default_rng(0)
    tp = np.column_stack([rng.uniform(9_000, 15_000, 800), rng.uniform(48_800, 54_400, 800)])
    pair = plan.pairs[0]
    rep = gap_report(plan, pair, tp[:3])
    ppp = {(p.a, p.b): 5 + 3 * i for i, p in enumerate(plan.pairs)}
    gaps = {(pair.a, pair.b): [rep.regions[k] for k in rep.gaps]}
    png = block_display(
        plan,
        tmp_path / "block.png",
        control=CONTROL,
        points_per_pair=ppp,
        gaps=gaps,
        tie_points_xy=tp,
        title="sample",
        crs="EPSG:2056",
    )
    assert png == tmp_path / "block.png"
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    img = imread(io.BytesIO(data), format="png")
    h, w = img.shape[:2]
    assert w > 1000
    assert h > 800
    rgb = img[:, :, :3]
    ink = np.mean(np.any(rgb < 0.9, axis=2))  # share of pixels that are not (near) white
    assert 0.02 < ink < 0.7
    # red of the gap hatching and the model lines is there
    red = (rgb[:, :, 0] > 0.7) & (rgb[:, :, 1] < 0.3) & (rgb[:, :, 2] < 0.3)
    assert red.sum() > 50
    pdf = block_display(plan, tmp_path / "block.pdf", control=CONTROL)
    assert pdf.read_bytes().startswith(b"%PDF")
    assert not list(tmp_path.glob("*.tmp*"))


def test_plain_plan_display_and_bad_suffix(tmp_path):
    plan = sample_plan()
    out = block_display(plan, tmp_path / "plan.png", dpi=60)
    img = imread(str(out))
    assert img[:, :, :3].std() > 0.05  # not blank
    with pytest.raises(FormatError, match=r"\.png or \.pdf"):
        block_display(plan, tmp_path / "plan.svg")


def test_helpers():
    assert [count_class(n) for n in (0, 5, 6, 17, 18, 500)] == [0, 0, 1, 1, 2, 2]
    assert nice_length(1234.0) == 1000.0
    assert nice_length(4999.0) == 2000.0
    assert nice_length(0.07) == pytest.approx(0.05)
