"""The outage-lengths dropout profile (issue 49): the field's lengths (1-60 s), longest first as
far as a drive has room, no overlap and >= 10 s of reception before each, deterministic for a
seed; the existing profiles unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from posbench.checks import check_dropouts
from posbench.errors import UsageError
from posbench.metrics.outage_lengths import length_classes
from posbench.scenarios.drive import GpsStream
from posbench.scenarios.dropouts import (
    FIELD_OUTAGE_LENGTHS_S,
    OUTAGE_SEPARATION_S,
    apply_dropouts,
    packed_outage_windows,
    parse_dropouts,
)


def _windows(t_end: float, seed: int = 0) -> np.ndarray:
    return packed_outage_windows(0.0, t_end, FIELD_OUTAGE_LENGTHS_S, np.random.default_rng(seed))


def _lengths(w: np.ndarray) -> list[float]:
    return sorted(np.round(w[:, 1] - w[:, 0], 9).tolist())


@pytest.mark.parametrize(
    "t_end, expected",
    [
        (11.5, []),  # 10 s of reception + 1 s + 1 s before the end: no room
        (12.0, [1.0]),
        (15.0, [2.0]),  # 2 s fits (13 s), 5 s (16 s) does not, 1 s no longer does
        (45.0, [30.0]),  # 41 s; 30 + 10 would need 61 s, 30 + 1 needs 52 s
        (72.9, [60.0]),
        (100.0, [10.0, 60.0]),  # 60 s (71 s), 30 (111) no, 10 (91) yes, 5 (106) no
        (190.0, [1.0, 2.0, 5.0, 10.0, 30.0, 60.0]),  # all (sum 108 + 6 x 10 + 1 = 169 s)
    ],
)
def test_the_lengths_that_fit_longest_first(t_end, expected):
    w = _windows(t_end)
    assert _lengths(w) == expected


@pytest.mark.parametrize("t_end", [12.0, 45.0, 100.0, 190.0, 517.7, 2000.0])
@pytest.mark.parametrize("seed", [0, 1, 7])
def test_windows_do_not_overlap_and_keep_their_reception(t_end, seed):
    w = _windows(t_end, seed)
    assert np.all(np.diff(w[:, 0]) > 0)  # sorted
    starts = np.concatenate([[0.0], w[:-1, 1]])
    assert np.all(w[:, 0] - starts >= OUTAGE_SEPARATION_S - 1e-9)  # reception before each
    assert w[-1, 1] <= t_end - 1.0 + 1e-9
    assert set(_lengths(w)) <= set(FIELD_OUTAGE_LENGTHS_S)


def test_long_streams_repeat_the_set_as_outages_does():
    # floor(T / (2 (108 + 60))) = 5 rounds on a 2000 s stream
    assert _lengths(_windows(2000.0)) == sorted(list(FIELD_OUTAGE_LENGTHS_S) * 5)


def test_deterministic_for_a_seed_and_placed_at_random():
    assert np.array_equal(_windows(517.7, 3), _windows(517.7, 3))
    a, b = _windows(517.7, 3), _windows(517.7, 4)
    assert _lengths(a) == _lengths(b) and not np.allclose(a, b)
    # the order of the lengths along the drive is shuffled, not always longest first
    firsts = {float(np.round(np.diff(_windows(517.7, s)[0])[0], 6)) for s in range(12)}
    assert len(firsts) > 2


def _gps(duration: float, dt: float = 0.1) -> GpsStream:
    t = np.arange(0.0, duration, dt)
    return GpsStream(t, 10.0 * t, np.zeros_like(t))


def test_the_profile_removes_the_fixes_and_each_outage_has_its_length_class():
    g = _gps(300.0)
    thin, outages = apply_dropouts(g, "outage-lengths", seed=5)
    b = np.asarray(outages)
    classes = length_classes(b[:, 1] - b[:, 0], FIELD_OUTAGE_LENGTHS_S)
    assert sorted(classes.tolist()) == list(FIELD_OUTAGE_LENGTHS_S)
    for (a, e), c in zip(outages, classes, strict=True):
        assert c <= e - a < c + 0.2 + 1e-9  # the window plus at most one fix interval each side
        assert not np.any((thin.t > a) & (thin.t < e))
    again, out2 = apply_dropouts(g, "outage-lengths", seed=5)
    assert out2 == outages and np.array_equal(again.t, thin.t)


def test_the_existing_profiles_are_unchanged_and_a_typo_is_one_error_line():
    assert parse_dropouts("outage-lengths")[0] == "outage-lengths"
    assert parse_dropouts("outages")[0] == "outages"
    assert parse_dropouts("outage:60") == ("outage", 60.0)
    with pytest.raises(UsageError, match="outage-lengths") as e:
        check_dropouts("outage-length")
    assert "\n" not in str(e.value)
