"""Make the bundled densification map DENS (deterministic: same bytes every run).

The seed's densification of ground control with the APY (FEASIBILITIES): photo 1 on
the left stage, photo 2 on the digitising tablet, photo 3 on the right stage; the
central and lateral points of each photo are transferred stereoscopically to the
photo on the tablet and these nine points measured there, then likewise with photos
2, 3 and 4, and 3, 4 and 5. The measurements are compiled "in the text mode"
(DATA EXCHANGE): one text ``PHOTO POINT`` per measurement at the point's photo
coordinates in millimetres, in a map without CRS (the photo on the tablet was oriented
on its fiducials), here layer ``c``.

Three photos (102, 103, 104) on the tablet, nine points each on a 3 x 3 pattern of
+-90 mm; the points of neighbouring photos share numbers where they were transferred
(the lateral points of one photo are the central points of the next), so that the
bundle program ties the photos together. Points are numbered (BLUH takes numbers).

Writes ``samples/densification/DENS.apa`` (APY ASCII). ``apygis convert
samples/densification/DENS.apa out/dens.patb --to patb`` makes the PAT-B bundle file,
``--to bluh`` BLUH's (docs/formats/patb.md, "The APY way").

Run: ``python samples/densification/make_densification.py [OUTDIR]``
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import apygis

BASE_MM = 92.0  # the air base at the photo scale: 60 % forward overlap of a 230 mm photo


def make() -> apygis.MapFile:
    m = apygis.MapFile("DENS", notes="bundle measurements: texts 'PHOTO POINT' at photo mm")
    lay = m.layer("c")
    rng = np.random.default_rng(1991)
    for k, photo in enumerate((102, 103, 104)):
        for col, dx in enumerate((-BASE_MM, 0.0, BASE_MM)):
            for row, dy in enumerate((90.0, 0.0, -90.0)):
                # point numbers run along the strip: column c of photo k is column c + k
                number = 1000 + 10 * (col + k) + row + 1
                x = round(dx + rng.normal(0.0, 2.0), 2)
                y = round(dy + rng.normal(0.0, 2.0), 2)
                lay.add_text(x, y, 0.0, f"{photo} {number}")
    return m


def main(outdir: Path) -> None:
    apygis.write(make(), outdir / "DENS.apa")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent)
