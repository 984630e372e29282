"""Fuzz every reader: random and mutated inputs may only raise ApygisError.

Each registered driver that reads needs a seed (a valid file of its format):
the APY ones are here, other drivers put theirs in a module
``tests/formats/fuzzseed_<driver>.py`` defining ``SEEDS = {name: fn}`` with
``fn(tmp_path) -> (bytes, file name)``. A driver without one fails
``test_every_reader_has_a_seed``.
Mutations are seeded, so a failure is reproducible from the printed case.

The readers of the block exchange formats (:mod:`apygis.aerotri.exchange`: PAT-B, BLUH,
COLMAP, OpenDroneMap, MicMac) are fuzzed the same way, one entry per kind of file
(``tests/aerotri/fuzz_exchange.py``: ``patb-im``, ``colmap-images``, ...); what they read
is written back with the format's writer.

The corpus ``tests/fuzz_corpus/<driver>/`` holds inputs that once broke a
reader (nested JSON, counts of 10**12, superscript digits, coordinates of
1e308, ...) and each driver's seeds: every file there is read by its driver
on every run (``test_corpus_file``), under a time limit, and may only raise
ApygisError. Mutations start from the seed or from a corpus file. An input
the mutations find that breaks a reader is saved into the corpus before the
test fails (``APYGIS_FUZZ_SAVE=0`` turns that off); fix the reader and commit
the file. ``APYGIS_FUZZ_CASES`` and ``APYGIS_FUZZ_SEED`` run more or other
cases to grow it; see ``tests/fuzz_corpus/README.md``.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import pkgutil
import re
import shutil
import signal
import struct
import zlib
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

import apygis
from apygis.errors import ApygisError
from apygis.formats import drivers
from tests.aerotri.fuzz_exchange import READERS as EXCHANGE
from tests.formats import strategies

N_CASES = int(os.environ.get("APYGIS_FUZZ_CASES", "1200"))
RNG_SEED = int(os.environ.get("APYGIS_FUZZ_SEED", "20261122"))
CORPUS = Path(__file__).parent / "fuzz_corpus"
TIME_LIMIT_S = 30  # per input: a hang guard, not a benchmark (the inputs take well under 5 s)
# files read together with the primary file of the same stem, not on their own
COMPANIONS = {"generate": (".csv", ".prj")}


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
SEEDS.update({name: seed for name, (_, seed, _) in EXCHANGE.items()})


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


def _readers() -> set[str]:
    return {name for name, d in drivers().items() if "r" in d.modes} | set(EXCHANGE)


def _reader(name: str):
    """The function that reads one file of the reader ``name`` (a driver or an exchange entry)."""
    return EXCHANGE[name][0] if name in EXCHANGE else drivers()[name].reader


# values that broke readers once (issue 9): overflowing, non-finite, huge, non-ASCII
# digits, lone surrogates as JSON escapes and as raw bytes, deep nesting
HOSTILE = (
    b"1e308",
    b"-1e308",
    b"1e999",
    b"NaN",
    b"-Infinity",
    b"inf",
    b"9" * 5000,
    b"1000000000000",
    "\u00b2".encode(),
    "\u0663".encode(),
    b"1_0",
    b"\\udcfc",
    b"\xed\xb3\xbc",
    b"\xff",
    b"[" * 2000,
    b"{" * 2000,
    b"\r",
    b"\n",
)
_NUMBER = re.compile(rb"-?[0-9][0-9.eE+-]*")


def mutate_hostile(data: bytes, rng: np.random.Generator) -> bytes:
    """A number of ``data`` (or any spot) replaced by one of :data:`HOSTILE`."""
    token = HOSTILE[rng.integers(0, len(HOSTILE))]
    numbers = [m.span() for m in _NUMBER.finditer(data[:200_000])]
    if numbers and rng.random() < 0.8:
        a, b = numbers[rng.integers(0, len(numbers))]
    else:
        a = b = int(rng.integers(0, len(data) + 1))
    return data[:a] + token + data[b:]


def test_every_reader_has_a_seed():
    readers = _readers()
    assert readers <= set(SEEDS), f"add fuzz seeds for: {sorted(readers - set(SEEDS))}"


def _corpus_files(driver: str) -> list[Path]:
    """The inputs of ``tests/fuzz_corpus/<driver>/`` (companion files excluded)."""
    folder = CORPUS / driver
    if not folder.is_dir():
        return []
    skip = COMPANIONS.get(driver, ())
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() not in skip)


def _corpus_cases() -> list:
    return [
        pytest.param(d, p, id=f"{d}/{p.name}")
        for d in sorted(_readers() | {p.name for p in CORPUS.iterdir() if p.is_dir()})
        for p in _corpus_files(d)
    ]


def test_every_reader_has_a_corpus():
    """Each reader's corpus folder holds at least its seeds, and no folder lacks a reader."""
    folders = {p.name for p in CORPUS.iterdir() if p.is_dir()}
    assert folders <= _readers(), f"corpus folders without a reader: {folders - _readers()}"
    for d in sorted(_readers()):
        names = [p.name for p in _corpus_files(d)]
        assert any(n.startswith("seed-") for n in names), f"{CORPUS / d}: no seed- file"


@contextmanager
def _time_limit(seconds: int, what: str):
    """Fail instead of hanging: SIGALRM interrupts the reader (main thread, POSIX)."""
    if not hasattr(signal, "SIGALRM"):  # pragma: no cover - Windows: no guard
        yield
        return

    def _timeout(signum, frame):
        raise TimeoutError(f"{what}: still reading after {seconds} s")

    old = signal.signal(signal.SIGALRM, _timeout)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.mark.parametrize(("driver", "path"), _corpus_cases())
def test_corpus_file(driver, path, tmp_path):
    """Every corpus file is read by its driver: a map or an ApygisError, in time.

    A map that was read is written as APY ASCII, which may refuse it (an
    ApygisError) but not crash: a reader must not return strings that cannot
    be encoded. A block an exchange reader returns is written back with its format's
    writer, likewise.
    """
    assert driver in _readers(), f"{path}: no reader named {driver!r}"
    for f in path.parent.iterdir():  # the file and its companions (GENERATE's CSV)
        if f.stem == path.stem and f.is_file():
            shutil.copyfile(f, tmp_path / f.name)
    message = None
    try:
        with _time_limit(TIME_LIMIT_S, str(path)), _memory_limit():
            m = _reader(driver)(str(tmp_path / path.name))
            # what a reader accepts can be written (no lone surrogates in notes or texts)
            if driver not in EXCHANGE:
                apygis.write(m, tmp_path / "written" / "back.apa")
            elif EXCHANGE[driver][2] is not None:
                EXCHANGE[driver][2](m, tmp_path / "written")
    except ApygisError as exc:
        message = str(exc)
    if message is not None:  # one line for the CLI, saying something
        assert message.strip()
        assert "\n" not in message.strip(), message


@contextmanager
def _memory_limit(extra: int = 4 << 30):
    """Refuse allocations beyond ``extra`` bytes more address space (Linux): a reader that
    asks for 116 TiB or touches 23 GB gets a MemoryError here, not the machine's OOM killer."""
    try:
        import resource

        with open("/proc/self/status") as fh:
            vm = next(int(ln.split()[1]) * 1024 for ln in fh if ln.startswith("VmSize:"))
        old = resource.getrlimit(resource.RLIMIT_AS)
        cap = vm + extra if old[1] == resource.RLIM_INFINITY else min(vm + extra, old[1])
        resource.setrlimit(resource.RLIMIT_AS, (cap, old[1]))
    except (ImportError, OSError, StopIteration, ValueError):  # pragma: no cover - not Linux
        yield
        return
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, old)


def _save_crash(driver: str, fname: str, data: bytes) -> Path | None:
    """Keep an input that broke a reader in the corpus; None if saving is off or fails."""
    if os.environ.get("APYGIS_FUZZ_SAVE", "1") == "0":
        return None
    path = CORPUS / driver / f"crash-{hashlib.sha1(data).hexdigest()[:12]}-{fname}"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    except OSError:  # pragma: no cover - a read-only checkout
        return None
    return path


@pytest.mark.parametrize("name", sorted(SEEDS))
def test_reader_survives_fuzzing(name, tmp_path):
    seed, fname = SEEDS[name](tmp_path)
    reader = _reader(name)
    rng = np.random.default_rng(RNG_SEED)
    target = tmp_path / "case" / fname
    target.parent.mkdir()
    outcomes = {"ok": 0, "error": 0}

    def attempt(case, data: bytes) -> None:
        target.write_bytes(data)
        try:
            with _time_limit(TIME_LIMIT_S, f"case {case}"), _memory_limit():
                reader(str(target))
            outcomes["ok"] += 1
        except ApygisError:
            outcomes["error"] += 1
        except Exception as exc:  # pragma: no cover - the failure report
            saved = _save_crash(name, fname, data)
            where = f"\nsaved as {saved}: commit it with the fix" if saved else ""
            pytest.fail(f"case {case}: {type(exc).__name__}: {exc}\ninput: {data[:200]!r}{where}")

    for case in range(N_CASES):
        data = mutate(seed, rng)
        if rng.random() < 0.5:
            data = mutate(data, rng)
        if name == "apy" and rng.random() < 0.6:
            data = _fix_apy_crc(data)  # get past the checksum to the field checks
        attempt(case, data)
    # the corpus inputs other than the seed, mutated in turn (their own random stream);
    # GENERATE companions are left out: the case names no attribute table
    # and, for drivers with hostile corpus files, hostile values put into the seed
    bases = {p.read_bytes() for p in _corpus_files(name) if p.stat().st_size < 2**18} - {seed}
    rng = np.random.default_rng(RNG_SEED + 1)
    for k, base in enumerate(sorted(bases)):
        for j in range(8):
            data = mutate(base, rng) if j else base
            if name == "apy" and rng.random() < 0.6:
                data = _fix_apy_crc(data)
            attempt(f"corpus {k}.{j}", data)
    for case in range(N_CASES // 4 if bases else 0):
        data = mutate_hostile(seed, rng)
        if rng.random() < 0.3:
            data = mutate_hostile(data, rng)
        if name == "apy":
            data = _fix_apy_crc(data)
        attempt(f"hostile {case}", data)
    assert outcomes["error"] > N_CASES // 4  # the mutations did reach the checks
