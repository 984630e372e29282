"""Revision sessions: the compilation engine wired to the instrument and the files.

:mod:`apygis.compile` is pure (events in, effects out, no I/O); this package
does the I/O around it: :mod:`~apygis.session.runner` (:class:`Session`,
the replay and live loops), :mod:`~apygis.session.journal` (the session
journal), :mod:`~apygis.session.decoder` (tablet reports and typed lines to
events) and :mod:`~apygis.session.lock` (one session per map).
"""

from apygis.session.decoder import ReportDecoder, decode_typed
from apygis.session.journal import Journal, JournalWriteError, StaleJournalError, read_journal
from apygis.session.lock import SessionLock, SessionLockedError, SessionLockError
from apygis.session.runner import (
    DisplayState,
    SaveError,
    Session,
    margin_map,
    run_live,
    run_tablet_stream,
)

__all__ = [
    "DisplayState",
    "Journal",
    "JournalWriteError",
    "ReportDecoder",
    "SaveError",
    "Session",
    "SessionLock",
    "SessionLockError",
    "SessionLockedError",
    "StaleJournalError",
    "decode_typed",
    "margin_map",
    "read_journal",
    "run_live",
    "run_tablet_stream",
]
