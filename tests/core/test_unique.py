"""unique_ints gives what np.unique gives (values, inverse, counts, first occurrences)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.unique import unique_ints


@pytest.mark.parametrize("n, high", [(0, 5), (1, 5), (7, 3), (5000, 40), (20000, 10**12)])
def test_the_same_arrays_as_numpy(n: int, high: int) -> None:
    keys = np.random.default_rng(n).integers(-high, high, n)
    got = unique_ints(keys)
    values, first, inverse, counts = np.unique(
        keys, return_index=True, return_inverse=True, return_counts=True
    )
    np.testing.assert_array_equal(got.values, values)
    np.testing.assert_array_equal(got.inverse, inverse.ravel())
    np.testing.assert_array_equal(got.counts, counts)
    np.testing.assert_array_equal(got.first, first)
    np.testing.assert_array_equal(got.values[got.inverse], keys)


def test_first_is_the_lowest_index_of_each_value() -> None:
    keys = np.array([5, 3, 5, 5, 3, 9])
    got = unique_ints(keys)
    assert got.values.tolist() == [3, 5, 9]
    assert got.first.tolist() == [1, 0, 5] and got.counts.tolist() == [2, 3, 1]
    assert got.inverse.tolist() == [1, 0, 1, 1, 0, 2]


def test_only_integer_vectors() -> None:
    with pytest.raises(ValueError, match="1-D integer"):
        unique_ints(np.array([0.5, 1.0]))
    with pytest.raises(ValueError, match="1-D integer"):
        unique_ints(np.zeros((2, 2), np.int64))
