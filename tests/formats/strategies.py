"""Hypothesis strategies for maps that fit the APY native formats."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

import apygis

cm_xy = st.integers(-999_999_999, 999_999_999).map(lambda v: v / 100.0)
cm_z = st.integers(-999_999, 999_999).map(lambda v: v / 100.0)
latin1_text = st.text(
    alphabet=st.characters(codec="latin-1", exclude_categories=("Cc",), exclude_characters="\x7f"),
    max_size=24,
).filter(lambda s: not any(0x80 <= ord(c) < 0xA0 for c in s))


@st.composite
def layers(draw, ext="r"):
    lay = apygis.Layer(ext)
    for _ in range(draw(st.integers(0, 6))):
        lay.add_symbol(draw(cm_xy), draw(cm_xy), draw(cm_z), draw(st.integers(0, 99)))
    for _ in range(draw(st.integers(0, 4))):
        n = draw(st.integers(1, 6))
        pts = [(draw(cm_xy), draw(cm_xy), draw(cm_z)) for _ in range(n)]
        closed = n >= 3 and draw(st.booleans())
        nums = lay.add_line(pts, code=draw(st.integers(0, 99)), closed=closed)
        lp = lay.line_points
        ends = lp["num"][(lp["back"] == -1) & (lp["num"] != nums[0])]
        if not closed and len(ends) and draw(st.booleans()):
            other = [int(v) for v in lp["num"] if int(v) not in nums]
            if other:
                target = draw(st.sampled_from(other))
                row = lp[lp["num"] == target][0]
                if row["side1"] == -1 or row["side2"] == -1:
                    lay.join(nums[0], target)
    for _ in range(draw(st.integers(0, 4))):
        lay.add_text(draw(cm_xy), draw(cm_xy), draw(cm_z), draw(latin1_text))
    return lay


@st.composite
def maps(draw):
    m = apygis.MapFile(
        draw(st.from_regex(r"[A-Za-z0-9_-]{1,32}", fullmatch=True)),
        scale=draw(st.none() | st.integers(1, 2**32 - 1)),
        crs=draw(st.sampled_from([None, "EPSG:2056", "EPSG:2229", "EPSG:25832"])),
        notes=draw(st.sampled_from(["", "one line", "two\nlines", "Zürich – Nord"])),
    )
    exts = draw(st.lists(st.from_regex(r"[a-z]{1,3}", fullmatch=True), max_size=4, unique=True))
    for ext in exts:
        m.add_layer(draw(layers(ext)))
    return m


def random_rows(rng: np.random.Generator, n: int):
    """Arrays for a full-speed synthetic layer: n line points as chains of 100."""
    from apygis.model.records import LINE_DTYPE

    lp = np.zeros(n, LINE_DTYPE)
    lp["num"] = np.arange(n)
    lp["x"] = np.round(rng.uniform(2.6e6, 2.7e6, n), 2)
    lp["y"] = np.round(rng.uniform(1.2e6, 1.3e6, n), 2)
    lp["z"] = np.round(rng.uniform(300, 900, n), 2)
    lp["code"] = rng.integers(0, 100, n)
    pos = np.arange(n) % 100
    lp["fwd"] = np.where(pos < 99, lp["num"] + 1, -1)
    lp["back"] = np.where(pos > 0, lp["num"] - 1, -1)
    lp["fwd"][-1] = -1
    lp["side1"] = lp["side2"] = -1
    return lp


def small_map():
    """A small map with a branch, a ring, a symbol, a text and two layers."""
    m = apygis.MapFile("FUZZ", scale=5000, crs="EPSG:2056", notes="fuzz")
    lay = m.layer("r")
    a = lay.add_line(
        [
            (2683000.0, 1247000.0, 420.0),
            (2683010.5, 1247001.25, 421.0),
            (2683020.0, 1247003.0, 422.5),
        ],
        code=11,
    )
    b = lay.add_line([(2683010.0, 1247020.0, 425.0), (2683010.0, 1247010.0, 423.0)], code=12)
    lay.join(b[-1], a[1])
    lay.add_line(
        [
            (2683100.0, 1247100.0, 430.0),
            (2683110.0, 1247100.0, 430.0),
            (2683110.0, 1247110.0, 430.0),
        ],
        code=21,
        closed=True,
    )
    lay.add_symbol(2683005.0, 1247005.0, 420.5, 6)
    lay.add_text(2683006.0, 1247006.0, 420.5, "Kirchweg")
    m.layer("e").add_symbol(2683050.0, 1247050.0, 431.25, 0)
    return m
