"""The PROCEED menu's display settings reach the session, also through a recovery."""

from __future__ import annotations

import pytest

from apygis.compile.engine import CrosshairScale, DisplayScale, Keys, Press
from apygis.compile.geometry import PlaneGeometry
from apygis.errors import RecordError
from apygis.session import DisplayState, Session

GEO = PlaneGeometry(2683000.0, 1247000.0, scale=5000)


def _set(sess, item: str, value: str) -> list:
    out = sess.handle(Press(item))
    out += sess.handle(Press("ENTER"))
    out += sess.handle(Keys(value))
    return out + sess.handle(Press("ENTER"))


def test_display_scale_and_crosshair_are_session_state_and_monitored(tmp_path):
    lines: list[str] = []
    s = Session(tmp_path / "T", GEO, layer="r", scale=5000, monitor=lines.append)
    assert s.display == DisplayState(1.0, 1.0)
    s.handle(Press("PROCEED"))
    assert DisplayScale(2.5) in _set(s, "1", "2.5")
    assert CrosshairScale(0.5) in _set(s, "3", "0.5")
    assert s.display == DisplayState(scale=2.5, crosshair=0.5)
    assert "  display scale factor 2.5x" in lines
    assert "  crosshair scale 0.5x" in lines
    out = _set(s, "1", "40")  # out of range: refused, asked again, the display keeps 2.5
    assert not any(isinstance(e, DisplayScale) for e in out)
    assert "  a value from 0.25 to 25.0, please" in lines
    assert s.display.scale == 2.5
    s.close()  # not terminated: the journal is kept

    lines.clear()
    s2 = Session(tmp_path / "T", GEO, layer="r", monitor=lines.append)
    assert s2.recovered > 0
    assert s2.display == DisplayState(scale=2.5, crosshair=0.5)  # replayed, not re-shown
    assert not any("display scale factor" in ln for ln in lines)
    s2.close()


@pytest.mark.parametrize(
    ("kind", "bad"), [(DisplayScale, 0.2), (DisplayScale, 25.5), (CrosshairScale, 4.5)]
)
def test_display_effects_refuse_values_out_of_range(kind, bad):
    with pytest.raises(RecordError, match="must be from"):
        kind(bad)
    with pytest.raises(RecordError):
        kind(float("nan"))
