"""Any journal or recording bytes: parsed, or one FormatError naming the file and line."""

from __future__ import annotations

import json

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from apygis.errors import FormatError
from apygis.instrument.replay import Replayer
from apygis.session.journal import read_journal

HEAD = {"journal": 2, "map": "", "layer": "r", "settings": {}, "files": {}}

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**400), 10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
)
values = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=8,
)
keys = st.sampled_from(["mark", "press", "keys", "files", "t", "ch", "hex", "dir", "x"])
records = st.one_of(
    st.dictionaries(keys, values, min_size=1, max_size=3),
    values,
)
head_changes = st.dictionaries(
    st.sampled_from(["journal", "map", "layer", "settings", "files", "format", "version",
                     "protocol", "counts_per_mm", "created"]),
    values,
    max_size=2,
)  # fmt: skip


def _dumps(obj) -> str:
    return json.dumps(obj, allow_nan=True)


@pytest.fixture(scope="module")
def empty_map_text():
    from apygis.formats import ascii as apa
    from apygis.model.map import MapFile

    return apa.encode(MapFile("F", scale=5000)).decode("utf-8")


@settings(max_examples=150, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(change=head_changes, lines=st.lists(records, max_size=4), junk=st.binary(max_size=6))
def test_journal_reader_raises_only_format_errors(tmp_path, empty_map_text, change, lines, junk):
    head = {**HEAD, "map": empty_map_text, **change}
    text = "\n".join(_dumps(x) for x in [head, *lines]).encode() + b"\n" + junk + b"\n"
    path = tmp_path / "F.journal"
    path.write_bytes(text)
    message = f"{path}: line "
    try:
        read_journal(path)
    except FormatError as exc:
        message = str(exc)
    assert message.startswith(f"{path}: line ")


@settings(max_examples=150, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(change=head_changes, lines=st.lists(records, max_size=4), junk=st.binary(max_size=6))
def test_recording_reader_raises_only_format_errors(tmp_path, change, lines, junk):
    head = {"format": "apygis-recording", "version": 1, **change}
    text = "\n".join(_dumps(x) for x in [head, *lines]).encode() + b"\n" + junk + b"\n"
    path = tmp_path / "f.rec"
    path.write_bytes(text)
    message = str(path)
    try:
        Replayer(path).chunks()
    except FormatError as exc:
        message = str(exc)
    assert message.startswith(str(path))
