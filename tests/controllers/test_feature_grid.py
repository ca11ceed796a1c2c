"""The feature laws' grid rows (:mod:`controllers.feature_grid`): the rows sanitised at
once are each row's own sanitising, to the last bit."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.feature_grid import sanitised, sanitised_rows


@pytest.mark.parametrize("m", [36, 18])
def test_the_grid_sanitised_at_once_is_each_row_sanitised(rng: np.random.Generator,
                                                          m: int) -> None:
    rows = rng.normal(size=(60, 3, m))
    rows[3, 2, 4] = np.nan  # a feature's acceleration unknown: the feature's rows go
    rows[7, 0, :3] = np.inf
    rows[9, 1, 5] = -0.0
    clean, known = sanitised_rows(rows)
    assert len(clean) == len(known) == 60
    for k, r in enumerate(rows):
        one, kept = sanitised(r)
        assert clean[k].tobytes() == one.tobytes()
        if kept is None:
            assert known[k].all()
        else:
            assert np.array_equal(known[k], kept)
    assert [k for k, x in enumerate(known) if not x.all()] == [3, 7]
    assert not known[3][3:6].any() and known[3][:3].all()
    assert np.isfinite(np.stack(clean)).all()
