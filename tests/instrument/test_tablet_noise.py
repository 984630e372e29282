"""Noisy-line properties: damage never invents a point, and undamaged packets come through.

The damage model (one damage at most a packet; see docs/protocols.md, "Noise"):

binary formats (packet length N)
    ``drop``  one byte of the packet removed;
    ``cut``   the packet cut short (a reconnect): only its first 1..N-1 bytes sent
              (but not a lone phasing byte right before a packet that lost its own);
    ``dup``   one byte of the packet sent twice;
    ``insert`` 1..3 bytes without the phasing bit inserted inside or after the packet;
    ``gap``   garbage before the packet: a byte with the phasing bit, then 0..N-2
              arbitrary bytes (line noise that looks like the start of a packet).
ASCII (fixed width)
    ``drop``, ``dup``, ``insert`` (one arbitrary byte) anywhere in the line.

Garbage without the phasing bit may also precede the whole stream. No checksum
protects these formats, so a burst of N arbitrary bytes *can* look like a
packet; the model keeps garbage runs shorter than a packet.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from apygis.instrument.tablet import AsciiParser, CalCompBinaryParser, MMBinaryParser, Report

from .test_tablet import ascii_reports, calcomp_reports, mm_reports, split

BINARY = {
    "mm": (MMBinaryParser, mm_reports),
    "calcomp": (CalCompBinaryParser, calcomp_reports),
}

low_bytes = st.binary(min_size=1, max_size=3).map(lambda b: bytes(c & 0x7F for c in b))


@st.composite
def binary_damage(draw, n: int):
    kind = draw(st.sampled_from(["none", "none", "drop", "cut", "dup", "insert", "gap"]))
    if kind in ("drop", "dup"):
        return kind, draw(st.integers(0, n - 1)), b""
    if kind == "cut":
        return kind, draw(st.integers(1, n - 1)), b""
    if kind == "insert":
        return kind, draw(st.integers(1, n)), draw(low_bytes)
    if kind == "gap":
        head = draw(st.integers(0x80, 0xFF))
        rest = draw(st.binary(max_size=n - 2))
        return kind, 0, bytes([head]) + rest
    return kind, 0, b""


def apply_binary(packet: bytes, damage) -> bytes:
    kind, pos, extra = damage
    if kind == "drop":
        return packet[:pos] + packet[pos + 1 :]
    if kind == "cut":
        return packet[:pos]
    if kind == "dup":
        return packet[: pos + 1] + packet[pos:]
    if kind == "insert":
        return packet[:pos] + extra + packet[pos:]
    if kind == "gap":
        return extra + packet
    return packet


def is_subsequence(got: list, sent: list) -> bool:
    it = iter(sent)
    return all(any(g == s for s in it) for g in got)


def run_binary(cls, reports, damages, lead, cuts):
    parser = cls()
    packets = [parser.encode(r) for r in reports]
    stream = lead + b"".join(apply_binary(p, d) for p, d in zip(packets, damages, strict=True))
    got = []
    for chunk in split(stream, cuts):
        got += parser.feed(chunk)
    got += parser.flush()
    return parser, stream, got


@pytest.mark.parametrize("fmt", sorted(BINARY))
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_binary_noise(fmt, data):
    cls, strategy = BINARY[fmt]
    n = cls.packet_len
    reports = data.draw(st.lists(strategy, min_size=1, max_size=25))
    damages = [data.draw(binary_damage(n)) for _ in reports]
    for i in range(len(damages) - 1):
        if damages[i][:2] == ("cut", 1) and damages[i + 1][:2] == ("drop", 0):
            # a lone phasing byte, then a packet that lost its own: indistinguishable
            # from a packet (outside the damage model)
            damages[i] = ("cut", 2, b"")
    lead = data.draw(low_bytes | st.just(b""))
    cuts = data.draw(st.lists(st.integers(0, 10_000), max_size=6))
    parser, stream, got = run_binary(cls, reports, damages, lead, cuts)

    # no invented point: what comes out is a subsequence of what was sent
    assert is_subsequence(got, reports), (got, reports)
    # every packet not touched by damage comes through
    for i, r in enumerate(reports):
        if damages[i][0] not in ("none", "gap"):
            continue
        nxt = damages[i + 1] if i + 1 < len(reports) else ("none", 0, b"")
        if nxt[0] == "drop" and nxt[1] == 0:
            continue  # the next packet's phasing byte is what ends this one
        assert r in got, (i, r, damages)
    expected = [
        r
        for i, r in enumerate(reports)
        if damages[i][0] in ("none", "gap")
        and not (i + 1 < len(reports) and damages[i + 1][:2] == ("drop", 0))
    ]
    assert is_subsequence(expected, got)
    # the counters add up
    assert parser.packets == len(got)
    assert parser.discarded_bytes == len(stream) - sum(len(r.raw) for r in got)
    if all(d[0] == "none" for d in damages) and not lead:
        assert parser.resyncs == 0
        assert got == reports


@pytest.mark.parametrize("fmt", sorted(BINARY))
@settings(max_examples=80, deadline=None)
@given(data=st.data())
def test_binary_noise_without_confirm(fmt, data):
    """confirm=False: safe against drops, cuts and noise bursts on alternate packets."""
    cls, strategy = BINARY[fmt]
    n = cls.packet_len
    reports = data.draw(st.lists(strategy, min_size=1, max_size=25))
    damages = []
    for i in range(len(reports)):
        d = data.draw(binary_damage(n)) if i % 2 == 0 else ("none", 0, b"")
        if d[0] in ("insert",) or (d[0] == "dup" and d[1] > 0):
            d = ("none", 0, b"")
        damages.append(d)
    packets = [cls().encode(r) for r in reports]
    stream = b"".join(apply_binary(p, d) for p, d in zip(packets, damages, strict=True))
    parser = cls(confirm=False)
    got = []
    for chunk in split(stream, data.draw(st.lists(st.integers(0, 10_000), max_size=6))):
        got += parser.feed(chunk)
    got += parser.flush()
    assert is_subsequence(got, reports)
    for i, r in enumerate(reports):
        next_header_lost = i + 1 < len(reports) and damages[i + 1][:2] == ("drop", 0)
        if damages[i][0] in ("none", "gap") and not next_header_lost:
            assert r in got


# --------------------------------------------------------------------------- ASCII


@st.composite
def ascii_damage(draw, line_len: int):
    kind = draw(st.sampled_from(["none", "none", "drop", "dup", "insert"]))
    if kind == "insert":
        return kind, draw(st.integers(0, line_len - 1)), draw(st.binary(min_size=1, max_size=1))
    if kind in ("drop", "dup"):
        return kind, draw(st.integers(0, line_len - 1)), b""
    return kind, 0, b""


@settings(max_examples=150, deadline=None)
@given(data=st.data())
@example(data=None)
def test_ascii_noise(data):
    if data is None:  # a pinned case: the LF of the first line dropped
        reports = [Report(1, 2, 3), Report(4, 5, 6, False)]
        damages = [("drop", 15, b""), ("none", 0, b"")]
        cuts = []
    else:
        reports = data.draw(st.lists(ascii_reports, min_size=1, max_size=25))
        damages = None
        cuts = data.draw(st.lists(st.integers(0, 10_000), max_size=6))
    parser = AsciiParser()
    lines = [parser.encode(r) for r in reports]
    if damages is None:
        damages = [data.draw(ascii_damage(len(line))) for line in lines]
    stream = b"".join(apply_binary(line, d) for line, d in zip(lines, damages, strict=True))
    got = []
    for chunk in split(stream, cuts):
        got += parser.feed(chunk)
    got += parser.flush()

    assert is_subsequence(got, reports), (got, reports, damages)
    for i, r in enumerate(reports):
        prev = damages[i - 1] if i else ("none", 0, b"")
        lf_lost = prev[0] == "drop" and prev[1] == len(lines[i - 1]) - 1
        if damages[i][0] == "none" and not lf_lost:
            assert r in got, (i, r, damages)
    assert parser.packets == len(got)


@pytest.mark.parametrize("cls", [MMBinaryParser, CalCompBinaryParser, AsciiParser])
@settings(max_examples=150, deadline=None)
@given(chunks=st.lists(st.binary(max_size=64), max_size=10))
def test_any_bytes_never_raise(cls, chunks):
    parser = cls()
    got = []
    for c in chunks:
        got += parser.feed(c)
    got += parser.flush()
    assert all(isinstance(r, Report) for r in got)
    assert parser.packets == len(got)
    assert parser.discarded_bytes + sum(len(r.raw) for r in got) <= sum(map(len, chunks))
