"""How far apart a truth's samples may be for a reference position between them (pure numpy).

A query's reference position is the truth interpolated at its time by a cubic spline
(:func:`posbench.replay.reference.truth_at`), only inside an interval between two truth
samples at most :data:`TRUTH_MAX_GAP_S` apart; a query in a longer gap has no reference
and is left out of the figures. The limit is in seconds, not in truth samples, on
purpose: what a spline may miss between two samples is the vehicle's own motion in
between, which grows with the time across, not with how often the truth happens to be
sampled. Under white jerk of density q the motion over a gap h wanders by the order of
sqrt(q h^5 / 20) (a spline through both ends takes back part of it): with q = 1 m^2/s^5
(a town drive) 0.7 mm across 0.1 s, 4 cm across 0.5 s, 22 cm across 1 s, against mean
prediction errors of 2 to 9 cm: a 1 Hz truth is no reference for them. Every shared
drive's truth is sampled at 10 Hz or faster.

:func:`truth_gap_note` says, in one line naming the truth's sample interval and the limit,
when a material share of a truth's span (over :data:`TRUTH_GAP_WARN_SHARE`) lies in longer
gaps: the data check warns with it and ``bench run`` names it where queries have no
reference.
"""

from __future__ import annotations

import numpy as np

#: the longest interval [s] between two truth samples a reference position is interpolated
#: across (module docstring: why seconds, and why 0.5 s)
TRUTH_MAX_GAP_S = 0.5
#: the share [-] of a truth's span in longer gaps from which :func:`truth_gap_note` speaks
TRUTH_GAP_WARN_SHARE = 0.01


def truth_gap_note(t: np.ndarray, max_gap_s: float = TRUTH_MAX_GAP_S) -> str:
    """One line on the part of a truth (sample times ``t`` [s], sorted) that has no
    reference position because its samples lie more than ``max_gap_s`` [s] apart, e.g.
    ``the truth is sampled every 1 s (median); a reference position is interpolated only
    across gaps up to 0.5 s, so 100 % of its span has none``; "" where that share of its
    span is at most :data:`TRUTH_GAP_WARN_SHARE` (or it has fewer than 2 samples)."""
    t = np.asarray(t, dtype=float)
    if t.size < 2 or not t[-1] > t[0]:
        return ""
    dt = np.diff(t)
    long = dt[dt > max_gap_s]
    share = float(long.sum() / (t[-1] - t[0]))
    if share <= TRUTH_GAP_WARN_SHARE:
        return ""
    median = float(np.median(dt))
    limit = f"a reference position is interpolated only across gaps up to {max_gap_s:g} s"
    none = f"so {100 * share:.3g} % of its span has none"
    if median > max_gap_s:
        return f"the truth is sampled every {median:.3g} s (median); {limit}, {none}"
    n = long.size
    return (
        f"the truth has {n} gap{'' if n == 1 else 's'} over {max_gap_s:g} s (longest "
        f"{float(long.max()):.3g} s; sampled every {median:.3g} s otherwise): {limit}, {none}"
    )
