"""Fuzzing of every orientation reader, with a corpus that grows.

Three parts:

* **corpus replay** — every file under ``tests/orient/fuzz_corpus/<reader>/``
  is read by its reader on every run; only a :class:`FormatError` naming the
  file is allowed (or a clean result), within 5 seconds. The corpus holds the
  hostile inputs of issue 9 (deep JSON nesting, integers beyond Python's
  int-string limit, ``1e400``, NaN/Infinity, zero, subnormal and huge scale
  factors, ...).
* **byte mutations** of the sample files (truncation, flipped and inserted
  bytes, random bytes, dropped and duplicated lines), seeded.
* **hostile mutations**: a random number of a sample replaced by a hostile
  token (``1e400``, thousands of digits, ``nan``, ``0``, ``5e-324``, ...) or
  the JSON wrapped in deep nesting, seeded.

A mutation that escapes (any exception other than an ApygisError, or more
than 5 seconds) is **saved into the corpus** as ``found-<hash>`` before the
test fails, so that the input is replayed from then on: commit it with the
fix. ``APYGIS_FUZZ_SEED`` and ``APYGIS_FUZZ_CASES`` change the seed and the
number of mutations per reader (default 4711 and 300).
"""

from __future__ import annotations

import hashlib
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest

from apygis.errors import ApygisError, FormatError
from apygis.orient.io import load_orientation
from apygis.orient.readers import (
    read_control,
    read_map_measurements,
    read_photo_file,
    read_photo_measurements,
)

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "orient"
CORPUS = Path(__file__).resolve().parent / "fuzz_corpus"
SEED = int(os.environ.get("APYGIS_FUZZ_SEED", "4711"))
CASES_PER_READER = int(os.environ.get("APYGIS_FUZZ_CASES", "300"))
LIMIT_S = 5.0

# corpus folder -> (sample file, reader, file suffix)
READERS = {
    "control": ("ZH1091-control.txt", read_control, ".txt"),
    "map": ("ZH1091-map.txt", read_map_measurements, ".txt"),
    "photos": ("ZH1091-photos.txt", read_photo_file, ".txt"),
    "photo-measurements": ("ZH1091-photo-measurements.txt", read_photo_measurements, ".txt"),
    "orientation": ("ZH1091-truth.orientation.json", load_orientation, ".json"),
}

HOSTILE_TOKENS = [
    b"1e400",
    b"-1e400",
    b"1" * 5000,
    b"-" + b"9" * 401,
    b"9223372036854775808",
    b"1e300",
    b"5e-324",
    b"0",
    b"-0.0",
    b"nan",
    b"NaN",
    b"inf",
    b"-Infinity",
    b"1_000",
    b"0x10",
    b'"1.5"',
    b"true",
    b"null",
    b"[]",
    b"{}",
]
_NUMBER = re.compile(rb"-?[0-9]+(?:\.[0-9]+)?(?:[eE][+-]?[0-9]+)?")


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


def _hostile(data: bytes, rng: np.random.Generator, is_json: bool) -> bytes:
    """Replace one to three numbers by hostile tokens, or (JSON) nest the document deeply."""
    if is_json and rng.random() < 0.15:
        depth = int(rng.choice([31, 33, 200, 5000]))
        return b"[" * depth + data + b"]" * depth
    spans = [m.span() for m in _NUMBER.finditer(data)]
    out = bytearray(data)
    picks = sorted(
        rng.choice(len(spans), size=min(len(spans), int(rng.integers(1, 4))), replace=False)
    )
    for k in reversed(picks):
        a, z = spans[int(k)]
        tok = HOSTILE_TOKENS[int(rng.integers(0, len(HOSTILE_TOKENS)))]
        if not is_json and tok[:1] in b'"[{tn':  # JSON-only values: keep text files textual
            tok = b"nan"
        out[a:z] = tok
    return bytes(out)


def _read(reader, path: Path) -> str:
    """Read ``path``; the message of the FormatError, '' for a clean result.

    Anything but an ApygisError propagates; an ApygisError that is not a
    FormatError (a reader must only raise FormatError) fails the assertion.
    """
    try:
        reader(path)
    except FormatError as exc:
        return str(exc)
    except ApygisError as exc:  # pragma: no cover - a reader bug
        raise AssertionError(
            f"{path}: a reader raised {type(exc).__name__}, not FormatError"
        ) from exc
    return ""


def _save_finding(folder: str, data: bytes, suffix: str) -> Path:
    target = CORPUS / folder / f"found-{hashlib.sha1(data).hexdigest()[:12]}{suffix}"
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_bytes(data)
    return target


def _check(folder: str, reader, path: Path, data: bytes, suffix: str, case) -> None:
    t0 = time.perf_counter()
    try:
        message = _read(reader, path)
    except Exception as exc:
        saved = _save_finding(folder, data, suffix)
        raise AssertionError(
            f"case {case}: {type(exc).__name__}: {exc!s:.200} -- input saved to {saved}"
        ) from exc
    elapsed = time.perf_counter() - t0
    if elapsed > LIMIT_S:
        saved = _save_finding(folder, data, suffix)
        raise AssertionError(f"case {case}: {elapsed:.1f} s -- input saved to {saved}")
    if message:
        assert path.name in message, (case, message)


def _corpus_files():
    for folder in sorted(READERS):
        for f in sorted((CORPUS / folder).glob("*")):
            if f.is_file():
                yield pytest.param(folder, f, id=f"{folder}/{f.name}")


def test_corpus_has_every_reader():
    for folder in READERS:
        assert any((CORPUS / folder).glob("*")), folder


@pytest.mark.parametrize(("folder", "path"), list(_corpus_files()))
def test_corpus_replays(folder, path, tmp_path):
    """Every stored hostile input: only a FormatError naming the file, within 5 s."""
    _sample, reader, suffix = READERS[folder]
    target = tmp_path / path.name  # a copy: the message must name the file read
    data = path.read_bytes()
    target.write_bytes(data)
    _check(folder, reader, target, data, suffix, path.name)


@pytest.mark.parametrize("folder", sorted(READERS))
def test_readers_survive_byte_mutations(folder, tmp_path):
    sample, reader, suffix = READERS[folder]
    seed = (SAMPLES / sample).read_bytes()
    rng = np.random.default_rng(SEED)
    target = tmp_path / f"mutant{suffix}"
    for case in range(CASES_PER_READER):
        data = _mutate(seed, rng)
        target.write_bytes(data)
        _check(folder, reader, target, data, suffix, case)


@pytest.mark.parametrize("folder", sorted(READERS))
def test_readers_survive_hostile_numbers(folder, tmp_path):
    sample, reader, suffix = READERS[folder]
    seed = (SAMPLES / sample).read_bytes()
    rng = np.random.default_rng(SEED + 1)
    target = tmp_path / f"hostile{suffix}"
    refused = 0
    for case in range(CASES_PER_READER):
        data = _hostile(seed, rng, suffix == ".json")
        target.write_bytes(data)
        _check(folder, reader, target, data, suffix, case)
        refused += bool(_read(reader, target))
    assert refused > CASES_PER_READER // 2  # the hostile tokens are mostly refused


def test_a_finding_is_saved_to_the_corpus(tmp_path, monkeypatch):
    """The mechanism that grows the corpus: an escaping input is stored, then the test fails."""
    monkeypatch.setattr(f"{__name__}.CORPUS", tmp_path)

    def broken_reader(path):
        raise ZeroDivisionError("float division by zero")

    p = tmp_path / "in.txt"
    p.write_bytes(b"1 0 0 0\n")
    with pytest.raises(AssertionError, match=r"ZeroDivisionError.*input saved to"):
        _check("control", broken_reader, p, b"1 0 0 0\n", ".txt", 0)
    saved = list((tmp_path / "control").glob("found-*.txt"))
    assert len(saved) == 1
    assert saved[0].read_bytes() == b"1 0 0 0\n"
