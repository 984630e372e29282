"""The model's bulk adds: many records at once, checked as the one-record adds are."""

from __future__ import annotations

import numpy as np
import pytest

import apygis
from apygis.errors import RecordError
from apygis.model.records import LINE_DTYPE, MAX_COORD, next_numbers


def test_add_symbols_numbers_by_the_model_rule_and_returns_the_numbers():
    lay = apygis.Layer("r")
    lay.add_symbol(0, 0, 0, 1)
    nums = lay.add_symbols(np.array([(1.0, 2.0, 3.0), (4.0, 5.0, 6.0)]), [7, 8])
    assert nums.tolist() == [2, 3]
    assert lay.symbols["code"].tolist() == [1, 7, 8]
    assert lay.add_symbols(np.zeros((2, 3)), 5, nums=[10, 20]).tolist() == [10, 20]
    assert lay.symbols["num"].tolist() == [1, 2, 3, 10, 20]


def test_the_numbering_rule_fills_free_numbers_past_9999():
    assert next_numbers(np.array([], np.int64), 2).tolist() == [1, 2]
    used = np.r_[np.arange(2, 10000)]
    assert next_numbers(used, 3).tolist() == [1, 0, 10000]
    lay = apygis.Layer("r")
    lay.add_symbols(np.zeros((1, 3)), 1, nums=[9999])
    assert lay.add_symbols(np.zeros((2, 3)), 1).tolist() == [1, 2]


def test_add_texts_checks_every_text():
    lay = apygis.Layer("t")
    assert lay.add_texts(np.zeros((2, 3)), ["Kirchweg", "Bach"]).tolist() == [1, 2]
    long = "Chilliwack General Hospital"  # 27 characters: the model keeps any length
    assert lay.add_texts(np.zeros((1, 3)), [long]).tolist() == [3]
    for bad, match in (
        ("two\nlines", "control"),
        ("Z\udcfcrich", "lone surrogate"),
    ):
        with pytest.raises(RecordError, match=match):
            lay.add_texts(np.zeros((2, 3)), ["fine", bad])
    assert lay.texts["text"].tolist() == ["Kirchweg", "Bach", long]  # nothing added


@pytest.mark.parametrize(
    ("xyz", "codes", "nums", "match"),
    [
        ([(0, 0, np.nan)], 1, None, "not finite"),
        ([(0, 2 * MAX_COORD, 0)], 1, None, "exceed"),
        ([(0, 0, 0)], 100, None, "0 to 99"),
        ([(0, 0, 0)], -1, None, "0 to 99"),
        ([(0, 0, 0)], True, None, "integers"),
        ([(0, 0, 0), (1, 1, 1)], [1, 2, 3], None, "one per"),
        ([(0, 0)], 1, None, r"\(n, 3\)"),
        ([(0, 0, 0)], 1, [-4], ">= 0"),
        ([(0, 0, 0), (1, 1, 1)], 1, [5, 5], "used twice"),
        ([(0, 0, 0)], 1, [1], "used twice"),  # the layer's symbol 1
    ],
)
def test_bad_symbols_are_refused_and_nothing_is_added(xyz, codes, nums, match):
    lay = apygis.Layer("r")
    lay.add_symbol(9, 9, 9, 1)
    with pytest.raises(RecordError, match=match):
        lay.add_symbols(np.array(xyz, dtype=float), codes, nums)
    assert len(lay.symbols) == 1


def _records(nums, fwd, back):
    rows = np.zeros(len(nums), LINE_DTYPE)
    rows["num"], rows["fwd"], rows["back"] = nums, fwd, back
    rows["side1"] = rows["side2"] = -1
    rows["x"] = np.arange(len(nums))
    return rows


def test_add_line_points_takes_references_as_they_are():
    lay = apygis.Layer("r")
    assert lay.add_line_points(_records([5, 7], [7, -1], [-1, 5])).tolist() == [5, 7]
    assert lay.counts()["lines"] == 1
    assert lay.validate() == []
    # a dangling reference is validate()'s to report, not a reason to refuse the values
    lay.add_line_points(_records([9], [42], [-1]))
    assert any(i.severity == "error" for i in lay.validate())


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [("x", np.inf, "not finite"), ("code", 120, "0 to 99"), ("fwd", -3, "reference")],
)
def test_add_line_points_refuses_bad_values(field, value, match):
    lay = apygis.Layer("r")
    rows = _records([1, 2], [2, -1], [-1, 1])
    rows[field][1] = value
    with pytest.raises(RecordError, match=match):
        lay.add_line_points(rows)
    assert len(lay.line_points) == 0


def test_add_line_points_refuses_a_number_in_use():
    lay = apygis.Layer("r")
    lay.add_line([(0, 0, 0), (1, 0, 0)], code=1)
    with pytest.raises(RecordError, match="used twice"):
        lay.add_line_points(_records([2], [-1], [-1]))


def test_from_arrays_checks_coordinates_and_codes():
    rows = _records([1, 2], [2, -1], [-1, 1])
    rows["y"][0] = np.nan
    with pytest.raises(RecordError, match="line point 1: Y"):
        apygis.Layer.from_arrays("r", line_points=rows)
    sym = np.zeros(1, apygis.Layer("r").symbols.dtype)
    sym["code"] = 100
    with pytest.raises(RecordError, match="outside 0-99"):
        apygis.Layer.from_arrays("r", symbols=sym)


def test_the_readers_bound_is_the_models():
    from apygis.formats import _readguard

    assert _readguard.MAX_COORD is MAX_COORD
