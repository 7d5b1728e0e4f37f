"""The detector's small-sample median gives numpy's values, NaN and empty input included."""

import numpy as np
from pattern_locator.vision.stats import median
import pytest


@pytest.mark.parametrize('n', [1, 2, 3, 8, 17, 40])
def test_median_is_numpys(n):
    rng = np.random.default_rng(n)
    for values in (rng.normal(size=n), np.round(rng.uniform(0, 5, n)),
                   rng.uniform(0, 255, n).astype(np.float32)):
        got = median(values)
        assert got == np.median(values)
        assert np.asarray(got).dtype == np.median(values).dtype
    table = rng.normal(size=(n, 3))
    assert np.array_equal(median(table, axis=0), np.median(table, axis=0))


def test_median_nan_and_empty_as_numpy():
    assert np.isnan(median(np.array([1.0, np.nan, 2.0])))
    with pytest.warns(RuntimeWarning):
        assert np.isnan(median(np.zeros(0)))
    with pytest.raises(ValueError, match='axis'):
        median(np.zeros((3, 2)), axis=1)
