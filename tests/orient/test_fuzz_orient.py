"""Byte-level fuzzing of the orientation readers, seeded from the sample files.

Mutated bytes (truncation, flipped and inserted bytes, random bytes,
dropped and duplicated lines) may only raise FormatError, never an
IndexError, ValueError or UnicodeDecodeError.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from apygis.errors import FormatError
from apygis.orient.io import load_orientation
from apygis.orient.readers import (
    read_control,
    read_map_measurements,
    read_photo_file,
    read_photo_measurements,
)

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "orient"
CASES = {
    "ZH1091-control.txt": read_control,
    "ZH1091-map.txt": read_map_measurements,
    "ZH1091-photos.txt": read_photo_file,
    "ZH1091-photo-measurements.txt": read_photo_measurements,
    "ZH1091-truth.orientation.json": load_orientation,
}


def _mutate(data: bytes, rng: np.random.Generator) -> bytes:
    b = bytearray(data)
    n = len(b)
    kind = rng.integers(0, 7)
    if kind == 0:
        return bytes(b[: rng.integers(0, n + 1)])
    if kind == 1:
        for _ in range(rng.integers(1, 6)):
            b[rng.integers(0, n)] = rng.integers(0, 256)
        return bytes(b)
    if kind == 2:
        pos = rng.integers(0, n + 1)
        return bytes(b[:pos]) + rng.bytes(int(rng.integers(1, 12))) + bytes(b[pos:])
    if kind == 3:
        return rng.bytes(int(rng.integers(0, 200)))
    if kind == 4:
        lines = bytes(b).split(b"\n")
        i, j = rng.integers(0, len(lines), 2)
        lines.insert(int(i), lines[int(j)])
        if rng.random() < 0.5:
            del lines[int(rng.integers(0, len(lines)))]
        return b"\n".join(lines)
    if kind == 5:
        digits = [k for k, c in enumerate(b) if 48 <= c <= 57]
        b[digits[rng.integers(0, len(digits))]] = int(rng.choice(list(b" -.ex=~#\t\xc3")))
        return bytes(b)
    pos = rng.integers(0, n)
    return bytes(b[:pos]) + bytes(b[pos + rng.integers(1, 40) :])


@pytest.mark.parametrize("name", sorted(CASES))
def test_readers_survive_fuzzing(name, tmp_path):
    seed = (SAMPLES / name).read_bytes()
    reader = CASES[name]
    rng = np.random.default_rng(4711)
    target = tmp_path / name
    for case in range(300):
        data = _mutate(seed, rng)
        target.write_bytes(data)
        try:
            reader(target)
            message = name
        except FormatError as exc:
            message = str(exc)
        assert name in message, (case, message)
