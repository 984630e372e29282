"""Compilation: the engine (a pure state machine) and the session around it."""
