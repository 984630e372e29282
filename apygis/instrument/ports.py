"""Opening serial ports: only with ``serial.serial_for_url``.

A device path (``/dev/ttyUSB0``), a pty, ``loop://``, ``socket://host:port``
and ``spy://`` then all work, for the tablet and for the motor controller
alike. pyserial is imported when a port is first opened.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["open_url"]


def open_url(url: str, fail: Callable[[Exception], Exception], **kwargs):
    """``serial.serial_for_url(url, **kwargs)``; a port that cannot be opened raises ``fail(exc)``.

    ``fail`` makes the caller's error (an :class:`~apygis.errors.InstrumentError`
    naming the port) from pyserial's ``SerialException``, an ``OSError`` or a
    ``ValueError`` (a bad URL or setting); the original is its ``__cause__``.

    Examples
    --------
    >>> from apygis.errors import InstrumentError
    >>> port = open_url("loop://", InstrumentError, timeout=0.01)
    >>> _ = port.write(b"ok"); port.read(2)
    b'ok'
    >>> open_url("nosuch://x", lambda e: InstrumentError(f"cannot open: {e}"))
    Traceback (most recent call last):
    ...
    apygis.errors.InstrumentError: cannot open: invalid URL, protocol 'nosuch' not known
    """
    import serial

    try:
        return serial.serial_for_url(url, **kwargs)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise fail(exc) from exc
