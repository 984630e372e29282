"""The grbl / grblHAL G-code dialect of the plate motors: commands, status reports, codes.

The four stepper motors that turn the optical plates are four axes of one
grblHAL controller (:mod:`apygis.instrument.motors` has the client,
:mod:`apygis.instrument.simgrbl` a simulated controller). This module is the
language both speak, with no I/O (``docs/protocols.md`` has it in full):

- positions are **absolute motor steps**, integers. The controller is set
  up with one step per unit on every axis (``$100=1 $101=1 $102=1
  $103=1``), so a G-code coordinate *is* a step count; the client puts the
  controller in ``G21 G90`` (millimetre units, absolute distances) when it
  connects;
- one move is one line: ``G0 X120 Y-35 Z98 A-40`` (rapid) or
  ``G1 X120 Y-35 F6000`` (feed in steps per minute), only the axes that
  move; ``G92 X0 Y0 Z0 A0`` sets the current position (the plates' zero,
  "eliminate parallax" in the seed);
- lines end with LF alone (grbl answers a CR LF pair with two ``ok``);
  every line is answered by ``ok`` or ``error:N`` (:data:`GRBL_ERRORS`);
  ``ALARM:N`` (:data:`GRBL_ALARMS`), ``[MSG:...]`` and the banner
  ``Grbl ...`` / ``GrblHAL ...`` (:data:`BANNER`) come unasked;
- ``?`` (no LF: a real-time command) asks for a status report
  ``<Idle|MPos:120.000,-35.000,98.000,-40.000|FS:0,0>``; Ctrl-X (0x18) is a
  soft reset, answered by the banner.

Examples
--------
>>> format_move(x=120, y=-35)
'G0 X120 Y-35'
>>> format_move(z=98, a=-40, feed=6000)
'G1 Z98 A-40 F6000'
>>> parse_status("<Idle|MPos:120.000,-35.000,0.000,0.000|FS:0,0>").steps
(120, -35, 0, 0)
"""

from __future__ import annotations

import operator
import re
from dataclasses import dataclass, field

from apygis.errors import ProtocolError

__all__ = [
    "AXES",
    "BANNER",
    "GRBL_ALARMS",
    "GRBL_ERRORS",
    "REALTIME",
    "RESET",
    "STATUS_QUERY",
    "MotorStatus",
    "format_move",
    "format_status",
    "parse_status",
]

#: The four axes: left photo x, y plates, right photo x, y plates.
AXES = ("X", "Y", "Z", "A")

#: grbl 1.1 error codes (the ones a plate driver meets).
GRBL_ERRORS = {
    1: "G-code words consist of a letter and a value; letter was not found",
    2: "missing the expected G-code word value or numeric value format is not valid",
    3: "grbl '$' system command was not recognized or supported",
    5: "homing cycle failure; homing is not enabled via settings",
    8: "grbl '$' command cannot be used unless grbl is idle",
    9: "G-code commands are locked out during alarm or jog state",
    11: "max characters per line exceeded; received command line was not executed",
    15: "jog target exceeds machine travel (soft limits)",
    20: "unsupported or invalid g-code command found in block",
    21: "more than one g-code command from same modal group found in block",
    22: "feed rate has not yet been set or is undefined",
    24: "two G-code commands that both require the use of the XYZ axis words were detected",
    25: "a G-code word was repeated in the block",
    26: "a G-code command implicitly or explicitly requires XYZ axis words in the block",
}

#: grbl 1.1 alarm codes.
GRBL_ALARMS = {
    1: "hard limit triggered",
    2: "soft limit: motion target exceeds machine travel",
    3: "reset while in motion; position may be lost",
    4: "probe fail",
    5: "probe fail",
    6: "homing fail: reset during active homing cycle",
    7: "homing fail: safety door was opened during homing",
    8: "homing fail: pull off travel failed to clear limit switch",
    9: "homing fail: could not find limit switch",
    10: "homing fail: second dual axis limit switch failed",
    11: "homing required",
}

#: The startup line of a controller (after power-up or a soft reset).
BANNER = re.compile(r"^(Grbl|GrblHAL)\s+\S+")
#: The real-time commands: acted on at once, never part of a line.
REALTIME = frozenset("?!~\x18")
#: Soft reset (Ctrl-X), answered by the banner.
RESET = b"\x18"
#: Status query (a real-time command, no LF), answered by a status report.
STATUS_QUERY = b"?"


def _int(name: str, value) -> int:
    try:
        return operator.index(value)
    except TypeError:
        raise ProtocolError(f"{name} must be an integer number of steps, not {value!r}") from None


def format_move(x=None, y=None, z=None, a=None, *, feed=None, word: str | None = None) -> str:
    """One G-code move line to absolute step positions (only the given axes).

    ``G0`` (rapid) without ``feed``, ``G1 ... F<feed>`` with it (steps per
    minute); ``word`` overrides the G word (``"G92"`` to set the position).
    """
    parts = [word or ("G0" if feed is None else "G1")]
    for axis, value in zip(AXES, (x, y, z, a), strict=True):
        if value is not None:
            parts.append(f"{axis}{_int(axis, value)}")
    if len(parts) == 1:
        raise ProtocolError("a move needs at least one of the axes X, Y, Z, A")
    if feed is not None and word is None:
        f = float(feed)
        if not f > 0:
            raise ProtocolError(f"feed must be positive, not {feed!r}")
        parts.append(f"F{f:g}")
    return " ".join(parts)


@dataclass(frozen=True)
class MotorStatus:
    """A parsed grbl status report ``<State|MPos:...|...>``.

    Attributes
    ----------
    state : str
        ``Idle``, ``Run``, ``Hold``, ``Jog``, ``Alarm``, ``Door``, ``Check``,
        ``Home`` or ``Sleep``.
    substate : int or None
        The number after ``Hold:`` or ``Door:``.
    mpos : tuple of float
        Machine position (one value an axis), when reported.
    wpos : tuple of float or None
        Work position, when reported (or derived from ``MPos`` and ``WCO``).
    fields : dict
        Every field as text (``{"FS": "0,0", ...}``).
    raw : str
        The report line.
    """

    state: str
    substate: int | None
    mpos: tuple[float, ...] | None
    wpos: tuple[float, ...] | None
    fields: dict[str, str] = field(default_factory=dict)
    raw: str = ""

    @property
    def steps(self) -> tuple[int, ...] | None:
        """Machine position rounded to whole steps."""
        return None if self.mpos is None else tuple(round(v) for v in self.mpos)

    @property
    def idle(self) -> bool:
        return self.state == "Idle"


def _floats(text: str, raw: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ProtocolError(f"bad number in grbl status report {raw!r}") from None


def parse_status(line: str) -> MotorStatus:
    """Parse a grbl 1.1 status report line, ``<Idle|MPos:0.000,0.000,0.000,0.000|FS:0,0>``."""
    raw = line.strip()
    if not (raw.startswith("<") and raw.endswith(">")) or len(raw) < 3:
        raise ProtocolError(f"not a grbl status report: {line!r}")
    parts = raw[1:-1].split("|")
    state, _, sub = parts[0].partition(":")
    if not state.isalpha():
        raise ProtocolError(f"bad machine state in grbl status report {line!r}")
    substate = int(sub) if sub.isdigit() else None
    fields = {}
    for p in parts[1:]:
        key, sep, value = p.partition(":")
        if not sep:
            raise ProtocolError(f"bad field {p!r} in grbl status report {line!r}")
        fields[key] = value
    mpos = _floats(fields["MPos"], raw) if "MPos" in fields else None
    wpos = _floats(fields["WPos"], raw) if "WPos" in fields else None
    if "WCO" in fields:
        wco = _floats(fields["WCO"], raw)
        if mpos is None and wpos is not None:
            mpos = tuple(w + o for w, o in zip(wpos, wco, strict=False))
        elif wpos is None and mpos is not None:
            wpos = tuple(m - o for m, o in zip(mpos, wco, strict=False))
    return MotorStatus(state, substate, mpos, wpos, fields, raw)


def format_status(state: str, mpos, wco=None) -> str:
    """A grbl 1.1 status report line (without CR LF), as a controller sends it.

    ``mpos`` and ``wco`` are one number an axis; ``WCO`` is left out when
    ``wco`` is None or all zero. :func:`parse_status` reads it back.

    >>> format_status("Idle", (5, 0, 0, -2))
    '<Idle|MPos:5.000,0.000,0.000,-2.000|FS:0,0>'
    >>> parse_status(format_status("Idle", (5, 0, 0, 0), (1, 0, 0, 0))).wpos
    (4.0, 0.0, 0.0, 0.0)
    """
    s = f"<{state}|MPos:" + ",".join(f"{v:.3f}" for v in mpos) + "|FS:0,0"
    if wco is not None and any(wco):
        s += "|WCO:" + ",".join(f"{v:.3f}" for v in wco)
    return s + ">"
