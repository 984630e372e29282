"""Pad files: a cursor whose buttons send other codes."""

from __future__ import annotations

import importlib

import pytest

from apygis.compile.engine import Press
from apygis.errors import FormatError
from apygis.instrument.pad import BUTTONS, load_pad, parse_pad
from apygis.instrument.tablet import Report, TabletConfig


def _report_decoder():
    """The session's ReportDecoder, wherever the session package has it (it is moving)."""
    for name in ("apygis.session", "apygis.session.decoder", "apygis.compile.session"):
        try:
            return importlib.import_module(name).ReportDecoder
        except (ImportError, AttributeError):
            continue
    raise ImportError("no ReportDecoder in apygis.session or apygis.compile.session")


def test_moved_buttons_leave_their_default_codes(tmp_path):
    f = tmp_path / "puck.pad"
    f.write_text("; thumb buttons\n13 ENTER\n11 proceed ; swapped\n\n")
    pad = load_pad(f)
    assert (pad[13], pad[11], pad[1]) == ("ENTER", "PROCEED", "1")
    assert list(pad.values()).count("ENTER") == 1
    assert len(parse_pad("5 ENTER\n", replace=True)) == 1
    dec = _report_decoder()(TabletConfig(), pad)
    assert _presses(dec.events(Report(10, 10, 13))[-1:]) == ["ENTER"]
    assert dec.events(Report(10, 10, 0)) == []
    assert _presses(dec.events(Report(10, 10, 11))) == ["PROCEED"]


def _presses(events) -> list:
    """The buttons of Press events (compared by name: the event classes are moving)."""
    return [e.button if type(e).__name__ == Press.__name__ else e for e in events]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("13\n", "line 1: expected 'CODE NAME'"),
        ("x ENTER\n", "expected 'CODE NAME'"),
        ("300 ENTER\n", "outside 1-255"),
        # str.isdigit() takes these, int() refuses (or reads) them: ASCII digits only
        ("\u00b2 ENTER\n", "line 1: expected 'CODE NAME', CODE in ASCII digits"),
        ("1\u00b9 ENTER\n", "line 1: expected 'CODE NAME', CODE in ASCII digits"),
        ("\u0663 ENTER\n", "line 1: expected 'CODE NAME', CODE in ASCII digits"),
        ("9" * 5000 + " ENTER\n", "line 1: button code 9999.*outside 1-255"),
        ("5 JUMP\n", "unknown button 'JUMP'"),
        ("5 ENTER\n6 ENTER\n", "line 2: ENTER is already on code 5"),
    ],
)
def test_bad_pad_files(text, match):
    with pytest.raises(FormatError, match=match):
        parse_pad(text, "p.pad")


def test_default_pad_is_unchanged_without_a_file():
    assert parse_pad("") == BUTTONS
