"""Compilation: the engine, a pure state machine (events in, effects out, no I/O).

:mod:`~apygis.compile.engine` (the modes and their states),
:mod:`~apygis.compile.events` (events and effects),
:mod:`~apygis.compile.geometry` (what the engine asks of an orientation) and
:mod:`~apygis.compile.oriented` (that, from an orientation). The session
around it (journal, instrument, files) is :mod:`apygis.session`.
"""
