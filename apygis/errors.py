"""The exceptions apygis raises.

Every failure a user can cause raises a subclass of :class:`ApygisError`. Each
subclass also derives from the built-in exception that fits it, so that code
which already catches ``ValueError`` or ``OSError`` keeps working
(``FormatError`` is a ``ValueError``, ``FileOverwriteError`` a
``FileExistsError``).

Messages name the file, the record (or line) and what was expected, so that a
user can find and fix the problem without a traceback.
"""

from __future__ import annotations

__all__ = [
    "ApygisError",
    "CRSError",
    "CapacityError",
    "ConvergenceError",
    "DegenerateGeometryError",
    "DriverError",
    "FileOverwriteError",
    "FormatError",
    "InstrumentError",
    "MeasurementError",
    "MotorError",
    "OrientationError",
    "ProtocolError",
    "RecordError",
    "RecordNotFoundError",
    "SymbolLibraryError",
    "TopologyError",
    "ValueRangeError",
    "ViewError",
    "WriteError",
]


class ApygisError(Exception):
    """Root of every error apygis raises on purpose."""


class FormatError(ApygisError, ValueError):
    """A file's content is not what its format requires.

    Parameters
    ----------
    message : str
        What was wrong and what was expected.
    path : str or os.PathLike, optional
        The file, prefixed to the message.
    record : str, optional
        Where in the file (``"line 12"``, ``"line point record 7"``, ...).
    """

    def __init__(self, message: str, path=None, record: str | None = None):
        self.path = None if path is None else str(path)
        self.record = record
        self.reason = message
        where = ": ".join(p for p in (self.path, record) if p)
        super().__init__(f"{where}: {message}" if where else message)


class ValueRangeError(FormatError):
    """A value does not fit the field a format gives it (too many digits, too long a text)."""


class CapacityError(ApygisError, OverflowError):
    """A table holds more records than a format (or an instrument) can take."""


class CRSError(ApygisError, ValueError):
    """A map has no CRS, a CRS is not valid, or points cannot be transformed."""


class DriverError(ApygisError, ValueError):
    """No driver fits a path or a name, or the driver cannot do what was asked."""


class FileOverwriteError(ApygisError, FileExistsError):
    """The target exists and overwriting was not asked for."""


class WriteError(ApygisError, OSError):
    """A file could not be written (a full disk, no permission, a target that is not a file).

    The message names the target, not the source, and the reason; nothing
    half-written is left behind. ``errno`` and ``filename`` are those of the
    ``OSError`` it stands for (the message stays as given).
    """

    def __str__(self) -> str:  # OSError would format errno and filename instead
        return str(self.args[0]) if self.args else ""


class RecordError(ApygisError, ValueError):
    """A record or its arguments are not valid (code outside 0-99, text too long, NaN, ...)."""


class TopologyError(ApygisError, ValueError):
    """Line references do not allow the operation (an open ring, a full junction, ...)."""


class RecordNotFoundError(ApygisError, LookupError):
    """No record with the given point number."""

    def __str__(self) -> str:  # LookupError would quote the message like a KeyError
        return str(self.args[0]) if self.args else ""


class SymbolLibraryError(ApygisError, ValueError):
    """A symbol library cannot do what was asked (symbol 00 is reserved, a cell is off the grid)."""


class OrientationError(ApygisError, ValueError):
    """An orientation (map, photo, model) cannot be computed from the data given."""


class DegenerateGeometryError(OrientationError):
    """Too few points, or points whose geometry does not determine the parameters.

    Collinear control for an affine transform, coplanar points for a DLT, four
    collinear points for a height correction, a parameter that the control
    does not determine: the message names what is missing.
    """


class MeasurementError(OrientationError):
    """A measurement set is incomplete or inconsistent.

    A point measured once where the method needs it measured twice, a
    measured point missing from the control, a photo without measurements.
    """


class ConvergenceError(OrientationError):
    """An iterative solution (Gauss-Newton, Newton inverse) did not converge."""


class ProtocolError(ApygisError, ValueError):
    """Bytes or values do not fit an instrument protocol.

    A report that a tablet format cannot carry (a button code above the
    format's range, a coordinate too large for its bit field), an unknown
    protocol or button name, a G-code word the motor dialect does not allow.
    """


class InstrumentError(ApygisError, OSError):
    """An instrument (tablet, motor controller, serial port) failed to do its part."""


class MotorError(InstrumentError):
    """The plate motor controller refused a command, raised an alarm or did not answer.

    Parameters
    ----------
    message : str
        What happened.
    port : str, optional
        The serial port or URL, prefixed to the message.
    line : str, optional
        The G-code line that was sent, when there is one.
    code : int, optional
        The grbl ``error:N`` code.
    alarm : int, optional
        The grbl ``ALARM:N`` code.
    """

    def __init__(self, message: str, *, port=None, line=None, code=None, alarm=None):
        self.port = None if port is None else str(port)
        self.line = line
        self.code = code
        self.alarm = alarm
        self.reason = message
        super().__init__(f"{self.port}: {message}" if self.port else message)


class ViewError(ApygisError, OSError):
    """The graphic display (``apygis view``, ``--view``) cannot be served.

    A host that is not an address of this machine, a port in use or not
    allowed, or the web server's package missing; the message names the
    address and the cause.
    """
