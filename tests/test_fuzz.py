"""Fuzz every reader: random and mutated inputs may only raise ApygisError.

Each registered driver that reads needs a seed (a valid file of its format):
the APY ones are here, other drivers put theirs in a module
``tests/formats/fuzzseed_<driver>.py`` defining ``SEEDS = {name: fn}`` with
``fn(tmp_path) -> (bytes, file name)``. A driver without one fails
``test_every_reader_has_a_seed``.
Mutations are seeded, so a failure is reproducible from the printed case.
"""

from __future__ import annotations

import importlib
import pkgutil
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

import apygis
from apygis.errors import ApygisError
from apygis.formats import drivers
from tests.formats import strategies

N_CASES = 1200


def _seed_apy(tmp_path):
    apygis.write(strategies.small_map(), tmp_path / "FUZZ")
    return (tmp_path / "FUZZ.r").read_bytes(), "FUZZ.r"


def _seed_ascii(tmp_path):
    apygis.write(strategies.small_map(), tmp_path / "FUZZ.apa")
    return (tmp_path / "FUZZ.apa").read_bytes(), "FUZZ.apa"


SEEDS = {"apy": _seed_apy, "ascii": _seed_ascii}
for _mod in pkgutil.iter_modules([str(Path(strategies.__file__).parent)]):
    if _mod.name.startswith("fuzzseed_"):
        SEEDS.update(importlib.import_module(f"tests.formats.{_mod.name}").SEEDS)


def _fix_apy_crc(data: bytes) -> bytes:
    if len(data) >= 64 and data[:4] == b"APYL":
        b = bytearray(data)
        struct.pack_into("<I", b, 60, zlib.crc32(bytes(b[64:])))
        return bytes(b)
    return data


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """One random mutation of ``data`` (or random bytes, or a line-level edit)."""
    b = bytearray(data)
    kind = rng.integers(0, 9)
    n = len(b)
    if kind == 0:
        return bytes(b[: rng.integers(0, max(n, 1))])
    if kind == 1:
        for _ in range(rng.integers(1, 9)):
            if n:
                b[rng.integers(0, n)] = rng.integers(0, 256)
        return bytes(b)
    if kind == 2:
        pos = rng.integers(0, n + 1)
        return bytes(b[:pos]) + rng.bytes(int(rng.integers(1, 16))) + bytes(b[pos:])
    if kind == 3 and n:
        pos = rng.integers(0, n)
        return bytes(b[:pos]) + bytes(b[pos + rng.integers(1, 32) :])
    if kind == 4 and n:
        pos = rng.integers(0, n)
        span = bytes(b[pos : pos + rng.integers(1, 64)])
        return bytes(b[:pos]) + span + bytes(b[pos:])
    if kind == 5:
        return rng.bytes(int(rng.integers(0, 300)))
    if kind == 6:  # line-level: drop, duplicate or swap lines
        lines = bytes(b).split(b"\n")
        i, j = rng.integers(0, len(lines), 2)
        op = rng.integers(0, 3)
        if op == 0:
            del lines[i]
        elif op == 1:
            lines.insert(i, lines[j])
        else:
            lines[i], lines[j] = lines[j], lines[i]
        return b"\n".join(lines)
    if kind == 7:  # a digit becomes something else, or a number changes
        digits = [k for k, c in enumerate(b) if 48 <= c <= 57]
        if digits:
            b[digits[rng.integers(0, len(digits))]] = rng.choice(list(b" -.x9\t\xc3"))
        return bytes(b)
    # a header count or word replaced
    for word in (b"SYMBOLS ", b"LINEPOINTS ", b"TEXTS ", b"LAYER ", b"SCALE ", b"CRS "):
        k = bytes(b).find(word)
        if k >= 0 and rng.random() < 0.5:
            end = bytes(b).find(b"\n", k)
            repl = word + str(rng.integers(-2, 20000)).encode()
            return bytes(b[:k]) + repl + bytes(b[end:])
    if n > 64:  # binary header fields
        off = int(rng.choice([4, 6, 8, 12, 44, 48, 52, 54, 56, 58]))
        b[off : off + 2] = rng.bytes(2)
    return bytes(b)


def test_every_reader_has_a_seed():
    readers = {name for name, d in drivers().items() if "r" in d.modes}
    assert readers <= set(SEEDS), f"add fuzz seeds for: {sorted(readers - set(SEEDS))}"


@pytest.mark.parametrize("name", sorted(SEEDS))
def test_reader_survives_fuzzing(name, tmp_path):
    seed, fname = SEEDS[name](tmp_path)
    reader = drivers()[name].reader
    rng = np.random.default_rng(20261122)
    target = tmp_path / "case" / fname
    target.parent.mkdir()
    outcomes = {"ok": 0, "error": 0}
    for case in range(N_CASES):
        data = mutate(seed, rng)
        if rng.random() < 0.5:
            data = mutate(data, rng)
        if name == "apy" and rng.random() < 0.6:
            data = _fix_apy_crc(data)  # get past the checksum to the field checks
        target.write_bytes(data)
        try:
            reader(str(target))
            outcomes["ok"] += 1
        except ApygisError:
            outcomes["error"] += 1
        except Exception as exc:  # pragma: no cover - the failure report
            pytest.fail(f"case {case}: {type(exc).__name__}: {exc}\ninput: {data[:200]!r}")
    assert outcomes["error"] > N_CASES // 4  # the mutations did reach the checks
