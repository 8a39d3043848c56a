"""Issue 40: the paper's cubic reference is solved in blocks of queries, so its memory does not
grow with the number of queries (which grows with a drive's span), and the blocks change no
figure."""

from __future__ import annotations

import numpy as np
import pytest

from posbench.replay import reference
from posbench.replay.reference import cubic_through_fixes


def _fixes(n: int = 400) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Irregular fixes (0.1-0.4 s apart, with one 3 s gap) along a random walk [m]."""
    rng = np.random.default_rng(7)
    steps = rng.uniform(0.1, 0.4, n)
    steps[n // 2] = 3.0
    return np.cumsum(steps), rng.normal(size=n).cumsum(), rng.normal(size=n).cumsum()


def test_blocks_give_the_same_answers_bit_for_bit(monkeypatch: pytest.MonkeyPatch) -> None:
    t, x, y = _fixes()
    tq = np.sort(np.random.default_rng(8).uniform(t[0] - 1.0, t[-1] + 1.0, 5000))
    whole = cubic_through_fixes(t, x, y, tq)
    assert 0 < np.isnan(whole[:, 0]).sum() < tq.size  # the gap and the ends are not covered
    monkeypatch.setattr(reference, "CUBIC_BLOCK", 7)  # 715 blocks, the last one short
    np.testing.assert_array_equal(cubic_through_fixes(t, x, y, tq), whole)


def test_a_block_bounds_the_working_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    """Beside the answer, the working arrays hold one block of ~1 kB a query (the documented
    figure behind :data:`~posbench.replay.reference.CUBIC_BLOCK`), however many queries."""
    import tracemalloc

    block = 4096
    monkeypatch.setattr(reference, "CUBIC_BLOCK", block)
    t, x, y = _fixes()
    tq = np.linspace(t[0], t[-1], 10 * block)
    tracemalloc.start()
    try:
        out = cubic_through_fixes(t, x, y, tq)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert np.isfinite(out).mean() > 0.9  # all but the gap and the ends
    assert peak - out.nbytes < 1200 * block, peak  # unblocked: ~10 x as much
