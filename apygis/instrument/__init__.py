"""The instrument: digitiser tablet, plate motors, simulator, session recordings.

This sub-package turns bytes into events and commands into bytes. It imports
neither the map model nor the orientation code: positions are tablet counts
or millimetres and motor steps; the compile engine and the session runner
convert to and from ground coordinates.

- :mod:`~apygis.instrument.tablet`: tablet protocol parsers and encoders
  (Summagraphics MM binary, CalComp binary, ASCII);
- :mod:`~apygis.instrument.pad`: the 27-button cursor pad (the button
  names and codes, the single definition) and pad files;
- :mod:`~apygis.instrument.grbl`: the G-code dialect of the four plate
  stepper motors (grbl / grblHAL): move lines, status reports, error codes;
- :mod:`~apygis.instrument.motors`: the motor controller client (serial
  connection, flow control, queue of unanswered lines);
- :mod:`~apygis.instrument.simgrbl`: a simulated grblHAL controller;
- :mod:`~apygis.instrument.simulator`: scripts of cursor moves, button
  presses and typing, turned into tablet bytes;
- :mod:`~apygis.instrument.replay`: record the raw bytes of a session and
  replay them.

Serial ports are opened only with ``serial.serial_for_url()``
(:func:`~apygis.instrument.ports.open_url`), so that
``loop://``, ``socket://host:port``, ``spy://`` and ptys work everywhere.
The formats are specified in ``docs/protocols.md`` and ``docs/button-pad.md``.
"""

from __future__ import annotations

from apygis.instrument.grbl import AXES, MotorStatus, format_move, parse_status
from apygis.instrument.motors import MotorController, open_controller
from apygis.instrument.pad import BUTTON_CODES, BUTTONS, button_code
from apygis.instrument.replay import Chunk, Recorder, RecordingPort, Replayer, ReplayPort
from apygis.instrument.simgrbl import SimulatedGrbl
from apygis.instrument.simulator import (
    KeyEvent,
    Script,
    ScriptBuilder,
    TabletEvent,
    VirtualInstrument,
    parse_script,
    read_script,
)
from apygis.instrument.tablet import (
    PROTOCOLS,
    AsciiParser,
    CalCompBinaryParser,
    MMBinaryParser,
    Parser,
    Report,
    TabletConfig,
    make_parser,
    read_reports,
)

__all__ = [
    "AXES",
    "BUTTONS",
    "BUTTON_CODES",
    "PROTOCOLS",
    "AsciiParser",
    "CalCompBinaryParser",
    "Chunk",
    "KeyEvent",
    "MMBinaryParser",
    "MotorController",
    "MotorStatus",
    "Parser",
    "Recorder",
    "RecordingPort",
    "ReplayPort",
    "Replayer",
    "Report",
    "Script",
    "ScriptBuilder",
    "SimulatedGrbl",
    "TabletConfig",
    "TabletEvent",
    "VirtualInstrument",
    "button_code",
    "format_move",
    "make_parser",
    "open_controller",
    "parse_script",
    "parse_status",
    "read_reports",
    "read_script",
]
