"""Tablet parsers: bit layouts, round trips, counters, plausibility, configuration."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from apygis.errors import ApygisError, ProtocolError
from apygis.instrument.tablet import (
    AsciiParser,
    CalCompBinaryParser,
    MMBinaryParser,
    Report,
    TabletConfig,
    encode_ascii,
    encode_calcomp,
    encode_mm,
    make_encoder,
    make_parser,
)

# --------------------------------------------------------------------------- strategies

prox = st.booleans()
mm_reports = st.builds(
    Report,
    st.integers(-16383, 16383),
    st.integers(-16383, 16383),
    st.integers(0, 7),
    prox,
)
calcomp_reports = st.builds(
    Report, st.integers(0, 65535), st.integers(0, 65535), st.integers(0, 27), prox
)
ascii_reports = st.builds(
    Report, st.integers(0, 99999), st.integers(0, 99999), st.integers(0, 27), prox
)
ascii_signed_reports = st.builds(
    Report, st.integers(-99999, 99999), st.integers(-99999, 99999), st.integers(0, 27), prox
)

CASES = {
    "mm": (MMBinaryParser, {}, mm_reports),
    "calcomp": (CalCompBinaryParser, {}, calcomp_reports),
    "ascii": (AsciiParser, {}, ascii_reports),
    "ascii-signed": (AsciiParser, {"width": 6, "signed": True}, ascii_signed_reports),
    "ascii-variable": (AsciiParser, {"width": None, "signed": True}, ascii_signed_reports),
}


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    out, prev = [], 0
    for p in [*points, len(data)]:
        out.append(data[prev:p])
        prev = p
    return out


def feed_all(parser, chunks) -> list[Report]:
    out = []
    for c in chunks:
        out += parser.feed(c)
    return out + parser.flush()


# --------------------------------------------------------------------------- bit layouts


def test_mm_bit_layout():
    # byte 0: 1 P T Sx Sy B2 B1 B0
    assert encode_mm(200, 3, button=2) == bytes([0x9A, 0x48, 0x01, 0x03, 0x00])
    assert encode_mm(-1, -2, button=0) == bytes([0x80, 0x01, 0x00, 0x02, 0x00])
    assert encode_mm(0, 0, proximity=False) == bytes([0xD8, 0, 0, 0, 0])
    assert encode_mm(16383, 0)[1:3] == b"\x7f\x7f"
    # the tablet ID bit is ignored by the parser
    r = MMBinaryParser(confirm=False).feed(bytes([0xBF, 0x01, 0x00, 0x02, 0x00]))
    assert r == [Report(1, 2, 7, True)]


def test_calcomp_bit_layout():
    # byte 0: 1 B4..B0 X15 X14; byte 3: 0 P 0 0 0 0 Y15 Y14
    assert encode_calcomp(65535, 65535, button=31, proximity=False) == bytes(
        [0xFF, 0x7F, 0x7F, 0x43, 0x7F, 0x7F]
    )
    assert encode_calcomp(20000, 300, button=27) == bytes.fromhex("ed1c2000022c")
    # a frame from a CalComp DrawingBoard (X 6317, Y 5903, button field 0b01111)
    (r,) = CalCompBinaryParser(confirm=False).feed(bytes.fromhex("bc312d002e0f"))
    assert (r.x_counts, r.y_counts, r.button, r.proximity) == (6317, 5903, 15, True)


def test_ascii_formats():
    assert encode_ascii(1234, 56, 11) == b"01234,00056,11\r\n"
    assert encode_ascii(1234, -56, 3, width=6, signed=True) == b"+01234,-00056,03\r\n"
    assert encode_ascii(7, 8, 0, False, width=None) == b"7,8,0,0\r\n"
    p = AsciiParser(width=None, signed=True)
    got = p.feed(b" 12 , -5 ,3\r\n+7,8,27,0\n1,2,3 , 1\r\r\n")
    assert [(r.x_counts, r.y_counts, r.button, r.proximity) for r in got] == [
        (12, -5, 3, True),
        (7, 8, 27, False),
        (1, 2, 3, True),
    ]
    assert p.discarded_bytes == 0
    # fixed width with space padding
    p = AsciiParser(width=5)
    assert p.feed(b"  123,00456, 7\r\n") == [Report(123, 456, 7)]


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("case", sorted(CASES))
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_round_trip(case, data):
    cls, opts, strategy = CASES[case]
    reports = data.draw(st.lists(strategy, max_size=20))
    cuts = data.draw(st.lists(st.integers(0, 10_000), max_size=8))
    parser = cls(**opts)
    stream = b"".join(parser.encode(r) for r in reports)
    got = feed_all(parser, split(stream, cuts))
    assert got == reports
    assert [g.raw for g in got] == [parser.encode(r) for r in reports]
    assert parser.packets == len(reports)
    assert parser.discarded_bytes == 0
    assert parser.resyncs == 0


@pytest.mark.parametrize("cls", [MMBinaryParser, CalCompBinaryParser, AsciiParser])
def test_byte_by_byte(cls):
    parser = cls()
    reports = [Report(i * 37, i * 11 + 5, i % 8, i % 3 != 0) for i in range(50)]
    stream = b"".join(parser.encode(r) for r in reports)
    got = feed_all(parser, [stream[i : i + 1] for i in range(len(stream))])
    assert got == reports


def test_confirm_latency():
    one, two = encode_calcomp(1, 2, 3), encode_calcomp(4, 5, 6)
    p = CalCompBinaryParser()
    assert p.feed(one) == []  # waits for the next phasing byte
    assert p.feed(two[:1]) == [Report(1, 2, 3)]
    assert p.feed(two[1:]) == []
    assert p.flush() == [Report(4, 5, 6)]
    assert p.flush() == []
    q = CalCompBinaryParser(confirm=False)
    assert q.feed(one) == [Report(1, 2, 3)]
    # an extra data byte after an emitted packet is discarded, not decoded
    assert q.feed(b"\x05" + two) == [Report(4, 5, 6)]
    assert q.discarded_bytes == 1
    assert q.resyncs == 1


# --------------------------------------------------------------------------- counters


def test_counters_garbage_and_reconnect():
    a, b, c = encode_mm(1, 1, 1), encode_mm(2, 2, 2), encode_mm(3, 3, 3)
    p = MMBinaryParser()
    # stray bytes, then a, then b cut short by a reconnect (c starts anew), then c
    got = p.feed(b"\x00\x7f\x10" + a + b[:3] + c) + p.flush()
    assert got == [Report(1, 1, 1), Report(3, 3, 3)]
    assert p.packets == 2
    assert p.discarded_bytes == 3 + 3
    assert p.resyncs == 2
    assert p.stats == {"packets": 2, "discarded_bytes": 6, "resyncs": 2, "rejected": 0}


def test_dropped_byte_never_decoded_shifted():
    pkts = [encode_calcomp(1000 + i, 2000 + i, i % 28) for i in range(5)]
    damaged = pkts[0] + pkts[1][:3] + pkts[1][4:] + pkts[2] + pkts[3] + pkts[4]
    p = CalCompBinaryParser()
    got = feed_all(p, [damaged])
    assert [r.x_counts for r in got] == [1000, 1002, 1003, 1004]
    assert p.discarded_bytes == 5
    assert p.resyncs == 1


def test_duplicated_byte_dropped_with_confirm():
    pkts = [encode_mm(10 * i, 5 * i, i % 8) for i in range(4)]
    damaged = pkts[0] + pkts[1][:2] + pkts[1][1:] + pkts[2] + pkts[3]
    p = MMBinaryParser()
    got = feed_all(p, [damaged])
    assert [r.x_counts for r in got] == [0, 20, 30]
    assert p.discarded_bytes == 6


def test_plausibility_rejects():
    cfg = TabletConfig(x_range=(0, 5000), y_range=(0, 5000), max_button=20)
    p = CalCompBinaryParser(cfg)
    stream = (
        encode_calcomp(100, 100, 1)
        + encode_calcomp(6000, 100, 1)  # outside the active area
        + encode_calcomp(100, 100, 25)  # button above max_button
        + bytes([0x80, 0, 0, 0x04, 0, 0])  # reserved bit set
        + encode_calcomp(200, 200, 2)
    )
    got = feed_all(p, [stream])
    assert got == [Report(100, 100, 1), Report(200, 200, 2)]
    assert p.rejected == 3
    assert p.discarded_bytes == 18
    assert p.resyncs == 1
    a = AsciiParser(cfg)
    got = a.feed(b"06000,00100,01\r\n00100,00100,21\r\n00100,00100,01\r\n")
    assert got == [Report(100, 100, 1)]
    assert a.rejected == 2
    m = MMBinaryParser(TabletConfig(x_range=(0, 100)))
    assert feed_all(m, [encode_mm(-5, 0), encode_mm(5, 0)]) == [Report(5, 0)]
    assert m.rejected == 1
    assert (a.discarded_bytes, a.resyncs) == (32, 1)
    u = AsciiParser(width=None)  # unsigned: a negative coordinate is rejected like the others
    assert u.feed(b"-5,3,1\r\n5,3,1\r\n") == [Report(5, 3, 1)]
    assert (u.rejected, u.discarded_bytes, u.resyncs) == (1, 8, 1)


@pytest.mark.parametrize(
    ("protocol", "options", "report"),
    [
        ("mm", {}, Report(-200, 16383, 7, False)),
        ("CalComp", {}, Report(20000, 300, 27)),
        ("ascii", {}, Report(1234, 56, 11)),
        ("ascii", {"width": None, "signed": True}, Report(-12, 5, 0, False)),
    ],
)
def test_make_encoder_is_the_parsers_encoder(protocol, options, report):
    encode = make_encoder(protocol, **options)
    data = encode(report.x_counts, report.y_counts, report.button, report.proximity)
    parser = make_parser(protocol, **options)
    assert data == parser.encode(report)
    assert parser.feed(data) + parser.flush() == [report]


def test_make_encoder_refuses_unknown_protocols_and_options():
    with pytest.raises(ProtocolError, match="unknown tablet protocol 'wacom'"):
        make_encoder("wacom")
    with pytest.raises(ProtocolError, match=r"mm: unexpected options \['width'\]"):
        make_encoder("mm", width=5)


def test_ascii_bad_lines_and_overlong():
    p = AsciiParser()
    stream = (
        b"0123,00056,11\r\n"  # a digit short
        b"01234,00056\r\n"  # no button field
        b"01234,-0056,01\r\n"  # negative while unsigned
        b"01234,00056,11,2\r\n"  # bad proximity
        b"\r\n" + b"x" * 200 + b"\r\n"  # blank line  # overlong garbage
        b"01234,00056,11\r\n"
    )
    got = feed_all(p, [stream[i : i + 7] for i in range(0, len(stream), 7)])
    assert got == [Report(1234, 56, 11)]
    assert p.resyncs == 1
    assert p.discarded_bytes == len(stream) - len(b"01234,00056,11\r\n")
    # a line without its LF at the end is not decoded
    q = AsciiParser()
    assert q.feed(b"01234,00056,11") == []
    assert q.flush() == []
    assert q.discarded_bytes == 14


def test_reset_forgets_partial():
    p = CalCompBinaryParser()
    p.feed(encode_calcomp(1, 1)[:4])
    p.reset()
    assert p.feed(encode_calcomp(2, 2)[1:]) == []
    assert p.flush() == []


# --------------------------------------------------------------------------- errors, config


@pytest.mark.parametrize(
    "call",
    [
        lambda: encode_mm(0, 0, button=8),
        lambda: encode_mm(16384, 0),
        lambda: encode_mm(1.5, 0),
        lambda: encode_calcomp(-1, 0),
        lambda: encode_calcomp(0, 65536),
        lambda: encode_calcomp(0, 0, button=32),
        lambda: encode_ascii(-1, 0),
        lambda: encode_ascii(100000, 0),
        lambda: encode_ascii(0, 0, button=100),
        lambda: make_parser("wacom"),
        lambda: make_parser("mm", width=5),
        lambda: AsciiParser(width=0),
        lambda: TabletConfig(counts_per_mm=0),
        lambda: TabletConfig(x_range=(5, 1)),
        # wrong types and absurd values: a ProtocolError, never TypeError or OverflowError
        lambda: TabletConfig(counts_per_mm=True),
        lambda: TabletConfig(counts_per_mm="40"),
        lambda: TabletConfig(counts_per_mm=10**400),
        lambda: TabletConfig(counts_per_mm=float("inf")),
        lambda: TabletConfig(max_button="27"),
        lambda: TabletConfig(x_range=("a", 1)),
        lambda: TabletConfig(x_range=5),
        lambda: TabletConfig(y_range=(0, float("nan"))),
        lambda: make_parser(5),
    ],
)
def test_errors(call):
    with pytest.raises(ProtocolError) as info:
        call()
    assert isinstance(info.value, ApygisError)
    assert isinstance(info.value, ValueError)


def test_mm_button_limit_message():
    with pytest.raises(ProtocolError, match=r"0\.\.7"):
        encode_mm(0, 0, button=11)


def test_tablet_config():
    cfg = TabletConfig()
    assert cfg.counts_per_mm == 40.0
    assert cfg.resolution_mm == 0.025
    assert cfg.counts_to_mm(4000) == 100.0
    assert cfg.mm_to_counts(0.0124) == 0
    assert cfg.mm_to_counts(0.0126) == 1
    np.testing.assert_array_equal(cfg.mm_to_counts(np.array([1.0, 2.5])), [40, 100])
    assert cfg.report_mm(Report(40, -80)) == (1.0, -2.0)
    lpi = TabletConfig.from_lpi(1000)
    assert lpi.counts_per_mm == pytest.approx(39.370078740157)
    assert lpi.mm_to_counts(25.4) == 1000


@given(st.integers(-(10**6), 10**6))
@example(0)
def test_config_counts_mm_round_trip(counts):
    cfg = TabletConfig(counts_per_mm=40)
    assert cfg.mm_to_counts(cfg.counts_to_mm(counts)) == counts


def test_make_parser_options():
    p = make_parser("ASCII", width=None, signed=True)
    assert isinstance(p, AsciiParser)
    assert p.width is None
    assert p.signed
    assert isinstance(make_parser("calcomp", confirm=False), CalCompBinaryParser)
