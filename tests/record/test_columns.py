"""Rows to Arrow columns: string columns built from raw buffers equal what pyarrow builds itself."""

from __future__ import annotations

import pyarrow as pa
import pytest

from swarmbox.record.columns import column


@pytest.mark.parametrize("values", [
    ["position"] * 1000,                      # one value throughout: the repeated-value path
    [""] * 7,
    ["ok"],
    ["näher"] * 5,                            # non-ASCII, repeated
    ["send", "recv", "recv", "drop"] * 50,    # mixed
    ["", "0,1,2", ""],
    ["ü", "a", ""],                           # mixed, non-ASCII
    [],
])
def test_string_columns_equal_pyarrows_own(values):
    got = column(values, pa.string())
    assert got.type == pa.string() and got.equals(pa.array(values, pa.string()))
    assert got.to_pylist() == values


def test_an_object_array_of_strings_converts_too():
    import numpy as np

    values = np.array(["OFFBOARD"] * 4 + ["LAND"], dtype=object)   # how the state buffers hold text
    assert column(values, pa.string()).to_pylist() == values.tolist()
    assert column(values[:4], pa.string()).to_pylist() == ["OFFBOARD"] * 4
