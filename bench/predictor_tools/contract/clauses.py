"""The contract's clauses: one function each, deciding pass or fail from the numbers it
measured on the inputs of :mod:`posbench.predictor_tools.contract.inputs` (see
:mod:`posbench.predictor_tools.contract` for what they are and what they prove); their ids,
descriptions and order are :data:`posbench.predictor_tools.contract.checker.CLAUSES`."""

from __future__ import annotations

import math
import pickle

import numpy as np

from posbench.predictor_tools.contract.inputs import (
    DRIVE_S,
    HORIZON_S,
    LINE_BOUND_M,
    PSD_TOL,
    SAME_M,
    STAND_BOUND_M,
    START_XY,
    WARMUP_S,
    Factory,
    Inputs,
    cut_prepared,
    last_observation_s,
    line_position,
)
from posbench.predictor_tools.contract.measure import (
    differences,
    metres,
    raised_line,
    run_replay,
    xy_text,
)
from posbench.replay.loop import GPS, IMU, QUERY, events, feed
from posbench.replay.prepare import PreparedDrive


def clause_reset(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """reset(): after a full replay, ``reset()`` and a second replay give the first one's
    answers, and the answer right after ``reset()`` is a fresh instance's."""
    p = factory()
    p.reset()
    t0 = float(inp.drive.gps.t[0])
    before = np.array([p.position_at(t0)], dtype=float)
    first = run_replay(factory, inp.drive, p)
    p.reset()
    after = np.array([p.position_at(t0)], dtype=float)
    second = run_replay(factory, inp.drive, p)
    d0 = differences(before, after)[0]
    if d0 > SAME_M:
        return False, (
            f"answer for t={t0:.2f} s right after reset() was {xy_text(after[0])}, a "
            f"fresh instance answered {xy_text(before[0])}"
        )
    d = differences(first.xy, second.xy)
    i = int(np.argmax(d))
    if d[i] > SAME_M:
        return False, (
            f"second replay after reset(): answer for t={first.t_query[i]:.2f} s "
            f"changed by {metres(d[i])} ({np.sum(d > SAME_M)} of {len(d)} answers "
            f"differ)"
        )
    return True, f"max |diff| {metres(float(d.max()))} over {len(d)} answers of two replays"


def clause_nan_before_first_fix(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """Before the first fix (IMU and speed samples allowed) every answer is (nan, nan)."""
    p = factory()
    p.reset()
    evs = [e for e in events(inp.line) if e[1] < inp.line_first_fix_s and e[0] != QUERY]
    asked: list[tuple[float, tuple[float, float]]] = [(0.0, p.position_at(0.0))]
    for k, t, a in evs:
        (p.observe_imu if k == IMU else p.observe_speed)(t, *a)
        for h in (0.0, HORIZON_S):
            asked.append((t + h, p.position_at(t + h)))
    bad = [(t, xy) for t, xy in asked if not (math.isnan(xy[0]) and math.isnan(xy[1]))]
    n_imu = sum(e[0] == IMU for e in evs)
    n_spd = len(evs) - n_imu
    if bad:
        t, xy = bad[0]
        return False, (
            f"answer for t={t:.2f} s before the first fix ({inp.line_first_fix_s:.2f}"
            f" s) was {xy_text(xy)}, not (nan, nan) ({len(bad)} of {len(asked)} answers)"
        )
    return True, (
        f"(nan, nan) at all {len(asked)} queries before the first fix "
        f"(after {n_imu} IMU and {n_spd} speed samples)"
    )


def no_look_ahead_cuts(prep: PreparedDrive, n: int = 4) -> list[float]:
    """The fix times [s] at which :func:`clause_no_look_ahead` cuts the drive: ``n`` fixes
    evenly spread over the drive, the last fix excluded."""
    t = prep.gps.t
    idx = np.unique(np.linspace(len(t) * 0.2, len(t) * 0.85, n).astype(int))
    return [float(t[i]) for i in idx]


def clause_no_look_ahead(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """Answers depend only on observations stamped at or before the time they are asked.

    Through its calls a predictor cannot see the future: the runner never gives it an
    observation stamped after a query's issue time. What is left to check is everything
    else it could read - the runner's drive in a caller's frame, a module global or file
    holding the recording. So the drive is replayed whole through one fresh instance, and
    cut after fix k (every observation stamped later withheld, nothing else changed) through
    another, for several k: both get the same calls in the same order up to the cut, so every
    answer of the cut replay must equal the whole replay's answer to the same query.

    What it proves: at these cuts of this drive, no answer depended on data stamped after
    its issue time that differs between the two replays. What it does not: a source that is
    the same in both (a truth file read by name, a cache shared between instances and filled
    by an earlier replay - ``reset`` and ``deterministic`` see that one, as the first replay
    in a process then differs from the later ones), or a predictor written to fool this check.
    After each cut replay the predictor is also asked for the time of its newest observation,
    which must not raise."""
    whole = run_replay(factory, inp.drive)
    worst, n_cmp, t_last = 0.0, 0, math.nan
    for t_cut in no_look_ahead_cuts(inp.drive):
        prep = cut_prepared(inp.drive, t_cut)
        p = factory()
        part = run_replay(factory, prep, p)
        t_last = last_observation_s(prep)
        try:
            p.position_at(t_last)
        except Exception as e:  # noqa: BLE001 - any exception fails the clause
            return (
                False,
                f"position_at({t_last:.2f} s), the newest observation's time, {raised_line(e)}",
            )
        nf = prep.future.t_query.size
        nw = prep.now.t_query.size
        ref = np.concatenate([whole.xy[:nf], whole.xy[len(inp.drive.future.t_query) :][:nw]])
        ref_tq = np.concatenate(
            [whole.t_query[:nf], whole.t_query[len(inp.drive.future.t_query) :][:nw]]
        )
        ref_ti = np.concatenate(
            [whole.t_issue[:nf], whole.t_issue[len(inp.drive.future.t_query) :][:nw]]
        )
        d = differences(part.xy, ref)
        n_cmp += d.size
        i = int(np.argmax(d))
        if d[i] > SAME_M:
            return False, (
                f"answer for t={ref_tq[i]:.2f} s (asked at {ref_ti[i]:.2f} s) changed "
                f"by {metres(d[i])} when the observations stamped after {t_cut:.2f} s "
                f"were withheld"
            )
        worst = max(worst, float(d.max()))
    cuts = ", ".join(f"{t:.1f}" for t in no_look_ahead_cuts(inp.drive))
    return True, (
        f"max |diff| {metres(worst)} over {n_cmp} answers, drive cut at {cuts} s vs whole"
    )


def clause_finite_after_first_fix(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """Every answer from the first fix on is finite (a drive with turns, a roundabout, a stop
    and a GPS dropout)."""
    a = run_replay(factory, inp.drive)
    bad = ~np.all(np.isfinite(a.xy), axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[np.argmin(a.t_issue[bad])])
        return False, (
            f"{int(bad.sum())} of {len(a)} answers not finite, first for "
            f"t={a.t_query[i]:.2f} s (asked at {a.t_issue[i]:.2f} s)"
        )
    return True, f"all {len(a)} answers finite ({inp.drive.drive.name}, 0-{DRIVE_S:g} s)"


def clause_straight_line(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """After a 2 s warm-up, answers are finite and within 0.5 m on a straight 15 m/s line with
    exact 5 Hz fixes (future queries 0.2 s ahead), and within 0.1 m of a standing car."""
    warm = inp.line_first_fix_s + WARMUP_S
    line = run_replay(factory, inp.line)
    keep = line.t_issue >= warm
    err = np.hypot(*(line.xy[keep] - line_position(line.t_query[keep])).T)
    stand = run_replay(factory, inp.stand)
    skeep = stand.t_issue >= warm
    drift = np.hypot(stand.xy[skeep, 0] - START_XY[0], stand.xy[skeep, 1] - START_XY[1])
    msgs = []
    ok = True
    for what, e, tq, bound in (
        ("line", err, line.t_query[keep], LINE_BOUND_M),
        ("standstill", drift, stand.t_query[skeep], STAND_BOUND_M),
    ):
        bad = ~np.isfinite(e)
        if bad.any():
            ok = False
            msgs.append(
                f"{what}: {int(bad.sum())} of {e.size} answers not finite, first for "
                f"t={tq[bad][0]:.2f} s"
            )
            continue
        i = int(np.argmax(e))
        if e[i] > bound:
            ok = False
            msgs.append(
                f"{what}: error {metres(e[i])} > {bound:g} m for t={tq[i]:.2f} s "
                f"({int(np.sum(e > bound))} of {e.size} answers)"
            )
        else:
            msgs.append(f"{what}: max error {metres(e[i])} over {e.size} answers")
    return ok, "; ".join(msgs)


#: probe query offsets [s] after the newest observation, in the order asked
PROBE_OFFSETS = (0.5, 0.05, 0.0, 0.2, 0.5, 0.0, 0.05, 0.2)


def clause_query_order(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """Queries out of time order and repeated (all at or after the newest observation) give
    finite answers, and the same time gets the same answer while no observation comes in."""
    p = factory()
    p.reset()
    evs = events(inp.drive)
    gps_i = [i for i, e in enumerate(evs) if e[0] == GPS]
    probe_at = {gps_i[len(gps_i) // 4], gps_i[len(gps_i) // 2], gps_i[3 * len(gps_i) // 4]}
    probe_at.add(next(i for i in range(gps_i[len(gps_i) // 3], len(evs)) if evs[i][0] == IMU))
    failures: list[str] = []
    n_asked = [0]

    def probe(i: int) -> None:
        if i not in probe_at or failures:
            return
        t_obs = evs[i][1]
        seen: dict[float, tuple[float, float]] = {}
        order = []
        for off in PROBE_OFFSETS:
            t = t_obs + off
            x, y = (float(v) for v in p.position_at(t))
            n_asked[0] += 1
            order.append(f"{off:g}")
            if not (math.isfinite(x) and math.isfinite(y)):
                failures.append(
                    f"answer for t={t:.2f} s ({off:g} s after the newest "
                    f"observation) is {xy_text((x, y))}"
                )
                return
            if off in seen:
                d = float(np.hypot(x - seen[off][0], y - seen[off][1]))
                if d > SAME_M:
                    failures.append(
                        f"t={t:.2f} s asked again (offsets asked: "
                        f"{', '.join(order)} s) moved {metres(d)}"
                    )
                    return
            else:
                seen[off] = (x, y)

    feed(p, evs, HORIZON_S, after=probe)
    if failures:
        return False, failures[0]
    return True, (
        f"{n_asked[0]} answers at {len(probe_at)} points of the drive, "
        f"{', '.join(f'{o:g}' for o in PROBE_OFFSETS)} s after the newest observation "
        "in this order: finite, repeats identical"
    )


def clause_picklable(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """A fresh instance and one in the middle of a drive survive pickle, and each copy then
    answers exactly like its original."""
    evs = events(cut_prepared(inp.drive, 20.0))
    mid = len(evs) // 2
    p = factory()
    p.reset()
    try:
        c = pickle.loads(pickle.dumps(p))
    except Exception as e:  # noqa: BLE001 - any exception fails the clause
        return False, f"pickling a fresh instance {raised_line(e)}"
    a = np.array(feed(p, evs, HORIZON_S, stop=mid)).reshape(-1, 3)
    b = np.array(feed(c, evs, HORIZON_S, stop=mid)).reshape(-1, 3)
    n_obs = sum(e[0] != QUERY for e in evs[:mid])
    try:
        c2 = pickle.loads(pickle.dumps(p))
    except Exception as e:  # noqa: BLE001
        return False, f"pickling after {n_obs} observations {raised_line(e)}"
    a2 = np.array(feed(p, evs, HORIZON_S, start=mid)).reshape(-1, 3)
    b2 = np.array(feed(c2, evs, HORIZON_S, start=mid)).reshape(-1, 3)
    worst = 0.0
    for what, x, y in (
        ("the copy of a fresh instance", a, b),
        (f"the copy made after {n_obs} observations", a2, b2),
    ):
        d = differences(x[:, 1:], y[:, 1:])
        i = int(np.argmax(d)) if d.size else 0
        if d.size and d[i] > SAME_M:
            return False, f"{what} answered t={x[i, 0]:.2f} s {metres(d[i])} away from the original"
        worst = max(worst, float(d.max()) if d.size else 0.0)
    return True, (
        f"max |diff| {metres(worst)} over {len(a) + len(a2)} answers of the copies "
        f"(fresh, and after {n_obs} observations)"
    )


def clause_deterministic(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """Two fresh instances replayed on the same drive give the same answers."""
    a = run_replay(factory, inp.drive)
    b = run_replay(factory, inp.drive)
    d = differences(a.xy, b.xy)
    i = int(np.argmax(d))
    if d[i] > SAME_M:
        return False, (
            f"answer for t={a.t_query[i]:.2f} s differs by {metres(d[i])} between two "
            f"fresh instances ({int(np.sum(d > SAME_M))} of {len(d)} answers)"
        )
    return True, f"max |diff| {metres(float(d.max()))} over {len(d)} answers of two instances"


def clause_covariance_psd(factory: Factory, inp: Inputs) -> tuple[bool, str]:
    """Where the predictor reports ``covariance_at(t)`` (2x2, m^2; None = "no uncertainty",
    the base default), it is finite, symmetric and positive semi-definite, at every fix and
    0.2 s later (from the first fix on)."""
    p = factory()
    cov = getattr(p, "covariance_at", None)
    if not callable(cov):
        return True, "not reported"
    p.reset()
    evs = events(cut_prepared(inp.drive, 20.0))
    n, min_eig = 0, math.inf
    bad: list[str] = []  # the first problem found (probing stops there)

    def probe(i: int) -> None:
        nonlocal n, min_eig
        if evs[i][0] != GPS or bad:
            return
        for t in (evs[i][1], evs[i][1] + HORIZON_S):
            answer = cov(t)
            if answer is None:
                continue
            c = np.asarray(answer, dtype=float)
            n += 1
            if c.shape != (2, 2) or not np.all(np.isfinite(c)):
                bad.append(
                    f"covariance_at({t:.2f} s) is not a finite 2x2 matrix: "
                    f"{np.array2string(c, precision=3, separator=', ')}"
                )
                return
            asym = abs(c[0, 1] - c[1, 0])
            if asym > PSD_TOL * max(1.0, float(np.abs(c).max())):
                bad.append(f"covariance_at({t:.2f} s) is not symmetric: |c01 - c10| = {asym:.3g}")
                return
            e = float(np.linalg.eigvalsh(c).min())
            min_eig = min(min_eig, e)
            if e < -PSD_TOL:
                bad.append(f"covariance_at({t:.2f} s) has eigenvalue {e:.3g} m^2 < 0")

    feed(p, evs, HORIZON_S, after=probe)
    if bad:
        return False, bad[0]
    if n == 0:
        return True, "not reported (covariance_at always None)"
    return True, f"{n} matrices symmetric, smallest eigenvalue {min_eig:.3g} m^2"
