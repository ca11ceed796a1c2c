"""``python -m benchmarks.perf.controllers``: the per-trial step and, with ``--arrays``, the
batch path on a batch of one, in one table."""

from __future__ import annotations

import math

import pytest

from benchmarks.perf import controllers as perf


def test_arrays_adds_the_batch_paths_column(capsys: pytest.CaptureFixture[str]) -> None:
    timings = perf.time_controllers(["computed-torque"], steps=20, repeats=1, arrays=True)
    assert [t.name for t in timings] == ["computed-torque", "joint-space"]
    for t in timings:
        assert t.refused == 0
        assert t.median_us > 0 and t.arrays_us > 0 and math.isfinite(t.arrays_us)
    assert "arrays us" in perf.format_timings(timings, "front").splitlines()[1]
    plain = perf.time_controllers(["joint-space"], steps=5, repeats=1)
    assert math.isnan(plain[0].arrays_us)
    assert "arrays us" not in perf.format_timings(plain, "front")
