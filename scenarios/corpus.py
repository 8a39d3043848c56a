"""The training corpus: seeded vehicle-dynamics drives that cover the driving envelope.

Random routes from :mod:`posbench.scenarios.synthetic`'s kinematic simulator, per profile
(:data:`PROFILES`), drawn by :mod:`posbench.scenarios.corpus_routes` (the profiles'
manoeuvres, lane changes and the vehicle's limits drawn per drive). Every drive starts at a
standstill.

Per drive, the vehicle's limits are drawn
(:class:`posbench.scenarios.corpus_routes.VehicleLimits`) and so are its sensors
(:class:`SensorSpec`: IMU at 50 or 100 Hz, accelerometer white noise 0.02-0.2 m/s^2 and
bias sigma 0.02-0.3 m/s^2, yaw noise 0.002-0.02 rad, yaw-rate noise 0.002-0.02 rad/s,
gyro bias sigma 0-0.005 rad/s). CAN speed, GPS fixes (the paper's fix-interval
distribution with late fixes, white + Gauss-Markov noise) and dropouts are those of
:func:`posbench.scenarios.synthetic.generate_drive`.

``meta.extra``: ``seed``, ``profile``, ``route`` (``"corpus-<profile>"``), ``segments``
(``[label, t_start, t_end]``, label one of :data:`posbench.scenarios.labels.LABELS`, as
:func:`posbench.scenarios.labels.label_times` sees the manoeuvre: U-turns ``turn``; lane changes
and creeping ``straight``; arcs and curves ``turn`` if the yaw rate at the speed the car
can take them exceeds 0.1 rad/s or the radius is < 50 m, else ``straight``; roundabouts
with a ring radius >= 30 m ``turn``), ``manoeuvres`` (``[kind, t_start, t_end]``, kind one of
:data:`posbench.scenarios.corpus_routes.MANOEUVRES`), ``gps_outages``, ``vehicle`` and
``sensors`` (the draws).
Times in seconds from the drive's start, positions in metres (ENU), as every Drive.

Seeds: drive ``i`` of corpus seed ``s`` uses generator seed ``100000 + 1000 s + i``
(:func:`corpus_seed`), far from the benchmark's own synthetic seeds (0..~2000) and
from ``predictors/lstm/train.py``'s (10000 + 1000 s + i).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from posbench.scenarios.corpus_routes import (
    MANOEUVRES,
    ProfileRoute,
    VehicleLimits,
    draw_limits,
    loguniform,
)
from posbench.scenarios.drive import FIXES_FROM_TRUTH, Drive, DriveMeta, TruthStream
from posbench.scenarios.labels import LABELS
from posbench.scenarios.synthetic import EPOCH_S
from posbench.scenarios.synthetic_motion import Segment, simulate
from posbench.scenarios.synthetic_sensors import (
    ORIGIN_LAT,
    ORIGIN_LON,
    can_speed_stream,
    gps_stream,
    imu_stream,
)

PROFILES = ("urban", "rural", "highway")
DEFAULT_MIX = (0.4, 0.35, 0.25)
SEED_BASE = 100_000


@dataclass(frozen=True)
class SensorSpec:
    """One drive's IMU: rate [Hz], accelerometer white noise and bias sigma [m/s^2], yaw
    noise [rad], yaw-rate noise and gyro bias sigma [rad/s]."""

    imu_hz: int
    accel_sd: float
    bias_sd: float
    yaw_sd: float
    yaw_rate_sd: float
    gyro_bias_sd: float


def draw_sensors(rng: np.random.Generator) -> SensorSpec:
    """An IMU: rate 50 or 100 Hz; noises log-uniform, biases uniform (module doc ranges)."""
    return SensorSpec(
        imu_hz=int(rng.choice([50, 100])),
        accel_sd=loguniform(rng, 0.02, 0.2),
        bias_sd=float(rng.uniform(0.02, 0.3)),
        yaw_sd=loguniform(rng, 0.002, 0.02),
        yaw_rate_sd=loguniform(rng, 0.002, 0.02),
        gyro_bias_sd=float(rng.uniform(0.0, 0.005)),
    )


def _est_time_s(seg: Segment, lim: VehicleLimits) -> float:
    """A rough duration [s] of a segment (speed capped by the lateral limit; 5 s per stop
    for braking and pulling away), to know how many blocks fill a drive."""
    if seg.kind == "stop":
        return seg.dwell_s + 5.0
    v = seg.speed_mps
    if seg.kind == "arc":
        v = min(v, math.sqrt(lim.ay_max * seg.radius_m))
    return seg.path_length_m / max(v, 0.3)


def _ay_window_m(segs: list[Segment], lim: VehicleLimits) -> float:
    """The curve-limit window [m] of :func:`posbench.scenarios.synthetic_motion.simulate`
    that keeps the smoothed speed within ``ay_max``: the speed kernels' reach
    (+-``v_smooth_s``) at the route's top speed, plus 2 m for the shift of the re-integrated
    path."""
    return lim.v_smooth_s * max(g.speed_mps for g in segs) + 2.0


def corpus_seed(seed: int, i: int) -> int:
    """Generator seed of drive ``i`` of corpus seed ``seed``: 100000 + 1000 seed + i."""
    return SEED_BASE + 1000 * int(seed) + int(i)


def corpus_drive(seed: int, profile: str, duration_s: float = 600.0) -> Drive:
    """One corpus drive of ``duration_s`` [s] (module doc); deterministic for its arguments.

    Args:
        seed: generator seed (route, vehicle limits, sensors, noise, fix times, dropouts).
        profile: one of :data:`PROFILES`.
        duration_s: length [s] the drive is cut to (> 1).
    """
    if profile not in PROFILES:
        raise ValueError(f"unknown corpus profile {profile!r}; choose one of {PROFILES}")
    if not duration_s > 1.0:
        raise ValueError(f"duration_s must be > 1 s, got {duration_s!r}")
    ss = np.random.SeedSequence([int(seed), zlib.crc32(f"corpus:{profile}".encode())])
    r_route, r_veh, r_sens, r_imu, r_speed, r_times, r_gps, r_drop = (
        np.random.default_rng(q) for q in ss.spawn(8)
    )
    lim, sens = draw_limits(r_veh), draw_sensors(r_sens)
    route = ProfileRoute(profile, r_route, lim)
    yaw0 = float(r_route.uniform(-np.pi, np.pi))
    segs = route.start()
    target = 1.1 * duration_s
    while True:
        est = sum(_est_time_s(g, lim) for g in segs)
        while est < target:
            blk = route.block()
            segs += blk
            est += sum(_est_time_s(g, lim) for g in blk)
        sim = simulate(segs, yaw0, **asdict(lim), ay_window_m=_ay_window_m(segs, lim))
        if sim.t[-1] >= duration_s:
            break
        target = est + 0.3 * duration_s  # the estimate was short: add blocks, simulate again
    n = int(np.searchsorted(sim.t, duration_s, "right"))
    t, x, y, yaw, v = sim.t[:n], sim.x[:n], sim.y[:n], sim.yaw[:n], sim.v[:n]
    yaw_rate, ax = sim.yaw_rate[:n], sim.ax[:n]
    truth = TruthStream(t, x, y, (yaw + np.pi) % (2 * np.pi) - np.pi, v)
    imu = imu_stream(
        t,
        yaw,
        v,
        yaw_rate,
        ax,
        r_imu,
        step=100 // sens.imu_hz,
        accel_sd=sens.accel_sd,
        bias_sd=sens.bias_sd,
        yaw_sd=sens.yaw_sd,
        yaw_rate_sd=sens.yaw_rate_sd,
        gyro_bias_sd=sens.gyro_bias_sd,
    )
    speed = can_speed_stream(t, v, r_speed)
    gps, outages = gps_stream(t, x, y, yaw, v, r_times, r_gps, r_drop)

    def cut(spans: list[list]) -> list[list]:
        out = [sp for sp in spans if sp[1] < t[-1]]
        if out:
            out[-1][2] = min(out[-1][2], float(t[-1]))
        return out

    meta = DriveMeta(
        fix_source=FIXES_FROM_TRUTH,
        name=f"corpus-{profile}-s{seed}",
        source=f"synthetic:corpus:{profile}:s{seed}",
        format="synthetic",
        epoch_s=EPOCH_S,
        origin_lat=ORIGIN_LAT,
        origin_lon=ORIGIN_LON,
        projection="enu",
        time_source="simulated",
        extra={
            "seed": int(seed),
            "profile": profile,
            "route": f"corpus-{profile}",
            "segments": cut(sim.segments),
            "manoeuvres": cut(sim.manoeuvres),
            "gps_outages": [list(o) for o in outages],
            "vehicle": asdict(lim),
            "sensors": asdict(sens),
        },
    )
    return Drive(meta=meta, gps=gps, imu=imu, speed=speed, truth=truth)


def corpus_plan(
    hours: float, seed: int = 0, duration_s: float = 600.0, mix: Sequence[float] = DEFAULT_MIX
) -> list[tuple[int, str]]:
    """The ``(generator seed, profile)`` of each drive of a corpus of >= ``hours`` [h].

    ``ceil(hours * 3600 / duration_s)`` drives, profiles interleaved so that every prefix
    keeps the ``mix`` (shares of urban, rural, highway; normalised) as closely as whole
    drives allow; drive ``i`` gets :func:`corpus_seed` ``(seed, i)``.
    """
    if not (math.isfinite(hours) and hours > 0):
        raise ValueError(f"hours must be > 0, got {hours!r}")
    if not duration_s > 1.0:
        raise ValueError(f"duration_s must be > 1 s, got {duration_s!r}")
    w = np.asarray(mix, dtype=float)
    if w.shape != (len(PROFILES),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(
            f"mix must be {len(PROFILES)} shares >= 0 (urban, rural, highway) "
            f"with a positive sum, got {tuple(mix)!r}"
        )
    w = w / w.sum()
    n = math.ceil(hours * 3600.0 / duration_s - 1e-9)
    if n > 1000:
        raise ValueError(
            f"{n} drives would leave corpus seed {seed}'s block of 1000 generator "
            "seeds; use longer drives (duration_s) or fewer hours"
        )
    counts = np.zeros(len(PROFILES))
    plan = []
    for i in range(n):
        k = int(np.argmax(w * (i + 1) - counts))  # the profile furthest behind its share
        counts[k] += 1
        plan.append((corpus_seed(seed, i), PROFILES[k]))
    return plan


def iter_corpus(
    hours: float, seed: int = 0, duration_s: float = 600.0, mix: Sequence[float] = DEFAULT_MIX
) -> Iterator[Drive]:
    """The drives of :func:`corpus_plan`, generated one at a time (constant memory)."""
    for s, profile in corpus_plan(hours, seed, duration_s, mix):
        yield corpus_drive(s, profile, duration_s)


def corpus_drives(
    hours: float, seed: int = 0, duration_s: float = 600.0, mix: Sequence[float] = DEFAULT_MIX
) -> list[Drive]:
    """A corpus of >= ``hours`` [h] of drives (see :func:`corpus_plan`), as a list.
    20 h are ~120 drives and ~1.3 GB in memory: prefer :func:`iter_corpus` for that."""
    return list(iter_corpus(hours, seed, duration_s, mix))


def drive_dynamics(d: Drive) -> dict[str, np.ndarray]:
    """Dynamics of a drive's 100 Hz truth: ``v`` [m/s], ``a_lat`` = v * yaw rate [m/s^2],
    ``kappa`` = yaw rate / v [1/m] (0 below 0.5 m/s, where heading is ill-defined),
    ``jerk`` = d^2 v / dt^2 [m/s^3]."""
    tr = d.truth
    if tr is None or tr.v is None or tr.yaw is None:
        raise ValueError(f"{d.name}: drive_dynamics needs a truth stream with v and yaw")
    yr = np.gradient(np.unwrap(tr.yaw), tr.t)
    v = tr.v
    kappa = np.where(v > 0.5, yr / np.maximum(v, 0.5), 0.0)
    return {
        "v": v,
        "a_lat": v * yr,
        "kappa": kappa,
        "jerk": np.gradient(np.gradient(v, tr.t), tr.t),
    }


def _stats(
    parts: dict[str, list[np.ndarray]],
    maxima: dict[str, float],
    seconds: float,
    label_s: dict[str, float],
    man_s: dict[str, float],
) -> dict:
    v = np.concatenate(parts["v"]) if parts["v"] else np.zeros(1)
    al = np.concatenate(parts["a_lat"]) if parts["a_lat"] else np.zeros(1)
    jk = np.concatenate(parts["jerk"]) if parts["jerk"] else np.zeros(1)
    pct = (1, 5, 25, 50, 75, 95, 99)
    tot = max(seconds, 1e-9)
    return {
        "hours": seconds / 3600.0,
        "speed_min_mps": maxima["v_min"],
        "speed_max_mps": maxima["v_max"],
        "speed_percentiles_mps": {
            str(p): float(q) for p, q in zip(pct, np.percentile(v, pct), strict=True)
        },
        "abs_lat_accel_max_mps2": maxima["a_lat"],
        "abs_lat_accel_p99_mps2": float(np.percentile(np.abs(al), 99)),
        "abs_curvature_max_inv_m": maxima["kappa"],
        "abs_jerk_p99_mps3": float(np.percentile(np.abs(jk), 99)),
        "abs_jerk_max_mps3": maxima["jerk"],
        "label_share": {k: label_s.get(k, 0.0) / tot for k in LABELS},
        "manoeuvre_share": {k: man_s.get(k, 0.0) / tot for k in MANOEUVRES},
    }


def envelope(drives: Iterable[Drive], subsample: int = 10) -> dict:
    """The driving envelope of drives with a truth stream (e.g. a corpus), overall and per
    profile (``meta.extra["profile"]``; drives without one count as ``"other"``).

    Returns ``{"all": stats, "profiles": {profile: stats}, "drives": n}``, stats holding
    ``hours``, ``speed_min_mps`` / ``speed_max_mps`` and ``speed_percentiles_mps``,
    ``abs_lat_accel_max_mps2`` / ``_p99_``, ``abs_curvature_max_inv_m``,
    ``abs_jerk_p99_mps3`` / ``abs_jerk_max_mps3``, and the share of time [0..1] per
    scenario label (``label_share``, from ``meta.extra["segments"]``) and per manoeuvre
    (``manoeuvre_share``, from ``meta.extra["manoeuvres"]``; ``segments`` if absent).
    Minima / maxima use every 100 Hz sample; percentiles every ``subsample``-th.
    """
    groups: dict[str, dict] = {}

    def group(name: str) -> dict:
        if name not in groups:
            groups[name] = {
                "parts": {"v": [], "a_lat": [], "jerk": []},
                "max": {"v_min": math.inf, "v_max": 0.0, "a_lat": 0.0, "kappa": 0.0, "jerk": 0.0},
                "seconds": 0.0,
                "labels": {},
                "man": {},
            }
        return groups[name]

    n = 0
    for d in drives:
        n += 1
        dyn = drive_dynamics(d)
        tr = d.truth
        assert tr is not None  # drive_dynamics raises on a drive without a truth
        span = float(tr.t[-1] - tr.t[0])
        prof = str(d.meta.extra.get("profile", "other"))
        spans = d.meta.extra.get("segments", [])
        mans = d.meta.extra.get("manoeuvres", spans)
        for g in (group("all"), group(prof)):
            for k in g["parts"]:
                g["parts"][k].append(dyn[k][::subsample])
            mx = g["max"]
            mx["v_min"] = min(mx["v_min"], float(dyn["v"].min()))
            mx["v_max"] = max(mx["v_max"], float(dyn["v"].max()))
            mx["a_lat"] = max(mx["a_lat"], float(np.abs(dyn["a_lat"]).max()))
            mx["kappa"] = max(mx["kappa"], float(np.abs(dyn["kappa"]).max()))
            mx["jerk"] = max(mx["jerk"], float(np.abs(dyn["jerk"]).max()))
            g["seconds"] += span
            for key, lst in (("labels", spans), ("man", mans)):
                for lab, a, b in lst:
                    g[key][lab] = g[key].get(lab, 0.0) + float(b - a)
    if not groups:
        raise ValueError("envelope needs at least one drive")
    out = {
        name: _stats(g["parts"], g["max"], g["seconds"], g["labels"], g["man"])
        for name, g in groups.items()
    }
    return {"all": out.pop("all"), "profiles": out, "drives": n}
