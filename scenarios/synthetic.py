"""The built-in synthetic data set: kinematic drives with GPS, IMU, CAN speed and exact truth.

A route is a list of :class:`posbench.scenarios.synthetic_motion.Segment` s (straight / arc /
stop), driven by the kinematic simulator (:func:`posbench.scenarios.synthetic_motion.simulate`:
smoothed curvature, a reachable speed profile under acceleration, braking and lateral
limits, stops with their dwell, resampled to 100 Hz); the sensors are simulated from its
truth (:mod:`posbench.scenarios.synthetic_sensors`). The simulator's limits are the
defaults of :func:`posbench.scenarios.synthetic_motion.simulate`'s keyword arguments (the
built-in data set); :mod:`posbench.scenarios.corpus` draws them per drive for the training
corpus.

Streams (t in seconds from the start, ENU metres about
:data:`posbench.scenarios.synthetic_sensors.ORIGIN_LAT`,
:data:`posbench.scenarios.synthetic_sensors.ORIGIN_LON`, the truth starting at (0, 0)):

- truth at 100 Hz: x, y, yaw (ENU, wrapped to [-pi, pi)), v;
- IMU at 50 Hz: ax = dv/dt, ay = v * yaw_rate (vehicle frame, y left) with white noise
  (0.05 m/s^2) and a small constant bias (sigma 0.05 m/s^2); yaw (noise 0.005 rad) and
  yaw_rate (noise 0.005 rad/s);
- CAN speed at 50 Hz (offset 10 ms from the IMU), noise 0.02 m/s, exactly 0 at standstill;
- GPS fixes at irregular 0.1-0.6 s intervals (the paper's distribution, with ~4 % late
  fixes 0.4-0.6 s), white noise 0.03 m plus a Gauss-Markov error (0.05 m, 30 s), and
  about one 1-2 s dropout per 40 s; lat/lon by the inverse ENU projection.

``meta.extra`` holds ``seed``, ``route`` and ``segments``: a list of
``[label, t_start, t_end]`` giving when each manoeuvre (straight, turn, roundabout,
start_stop = a standstill) happens.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable

import numpy as np

from posbench.scenarios.drive import FIXES_FROM_TRUTH, Drive, DriveMeta, TruthStream
from posbench.scenarios.synthetic_motion import Segment, simulate, stop, straight, turn
from posbench.scenarios.synthetic_sensors import (
    ORIGIN_LAT,
    ORIGIN_LON,
    can_speed_stream,
    gps_stream,
    imu_stream,
    wrap_angle,
)

EPOCH_S = 1_700_000_000.0
DEFAULT_ROUTES = ("mixed", "turns", "roundabout", "stop_and_go")


def roundabout(
    rng: np.random.Generator,
    j: Callable[[float, float], float],
    radius_m: float | None = None,
    speed_mps: float | None = None,
) -> list[Segment]:
    """Enter with a right turn, ~270 deg counter-clockwise around the ring, exit right.

    Default (both ``None``): ring radius 15-20 m at 7 m/s, entry / exit radius 10-12 m at
    6 m/s (the draws of the built-in routes). With ``radius_m`` [m] (and ``speed_mps``, the
    ring's target speed [m/s], default 7): entry / exit radius 0.6 x the ring's (6-15 m) at
    0.85 x the ring speed, ring angle 240-300 deg.
    """
    entry = j(30, 40)
    if radius_m is None:
        r_in = j(10, 12)
        ring = Segment(
            "arc",
            angle_rad=np.radians(j(260, 280)),
            radius_m=j(15, 20),
            speed_mps=7.0,
            label="roundabout",
            cont=True,
        )
        r_out, v_io = j(10, 12), 6.0
    else:
        v_ring = 7.0 if speed_mps is None else float(speed_mps)
        r_in = r_out = float(np.clip(0.6 * radius_m, 6.0, 15.0))
        ring = Segment(
            "arc",
            angle_rad=np.radians(j(240, 300)),
            radius_m=float(radius_m),
            speed_mps=v_ring,
            label="roundabout",
            cont=True,
        )
        v_io = 0.85 * v_ring
    return [
        turn(-entry, r_in, v_io, "roundabout"),
        ring,
        Segment(
            "arc",
            angle_rad=np.radians(-entry),
            radius_m=r_out,
            speed_mps=v_io,
            label="roundabout",
            cont=True,
        ),
    ]


def route_segments(route: str, rng: np.random.Generator) -> list[Segment]:
    """The segment list of a named route, lengths/speeds jittered by ``rng``."""

    def j(lo: float, hi: float) -> float:
        return float(rng.uniform(lo, hi))

    side = 1.0 if rng.random() < 0.5 else -1.0
    if route == "mixed":
        return [
            straight(j(70, 90), j(13, 15)),
            turn(-90, j(10, 13), 6.0),
            straight(j(110, 140), j(15, 18)),
            *roundabout(rng, j),
            straight(j(80, 100), j(11, 13)),
            stop(j(4, 6)),
            straight(j(100, 120), j(14, 16)),
            turn(90, j(12, 15), 6.5),
            straight(j(120, 150), j(16, 19)),
        ]
    if route == "turns":
        return [
            straight(j(60, 80), j(11, 13)),
            turn(90 * side, j(10, 12), 5.5),
            straight(j(90, 110), j(12, 14)),
            turn(-90 * side, j(10, 12), 5.5),
            straight(j(70, 90), j(11, 13)),
            turn(-90 * side, j(12, 14), 6.0),
            straight(j(100, 120), j(13, 15)),
            turn(90 * side, j(10, 12), 5.5),
            straight(j(80, 100), j(12, 14)),
            stop(j(3, 5)),
            straight(j(60, 80), j(10, 12)),
            turn(90 * side, j(10, 12), 5.5),
            straight(j(80, 100), j(13, 15)),
        ]
    if route == "roundabout":
        return [
            straight(j(100, 120), j(13, 15)),
            *roundabout(rng, j),
            straight(j(170, 200), j(15, 18)),
            *roundabout(rng, j),
            straight(j(140, 170), j(14, 17)),
        ]
    if route == "stop_and_go":
        return [
            straight(j(50, 70), j(10, 12)),
            stop(j(5, 8)),
            straight(j(60, 80), j(11, 13)),
            stop(j(3, 5)),
            straight(j(30, 40), j(8, 10)),
            stop(j(6, 9)),
            straight(j(90, 110), j(12, 14)),
            turn(90 * side, j(10, 12), 5.5),
            straight(j(50, 70), j(10, 12)),
            stop(j(4, 6)),
            straight(j(80, 100), j(12, 14)),
        ]
    if route == "straight":
        return [
            straight(j(400, 500), j(16, 20)),
            straight(j(300, 400), j(10, 12)),
            straight(j(400, 500), j(17, 20)),
        ]
    raise ValueError(
        f"unknown synthetic route {route!r}; choose one of {(*DEFAULT_ROUTES, 'straight')}"
    )


ROUTES = (*DEFAULT_ROUTES, "straight")


def generate_drive(
    seed: int = 0, name: str | None = None, route: str = "mixed", duration_s: float | None = None
) -> Drive:
    """One synthetic drive (see module doc). Deterministic for (seed, route, duration_s).

    Args:
        seed: random seed (route jitter, start heading, sensor noise, fix times, dropouts).
        name: drive name; default ``"synthetic-<route>-s<seed>"``.
        route: one of :data:`ROUTES`.
        duration_s: cut the drive to this length [s]; the route repeats if it is shorter.
    """
    if route not in ROUTES:
        raise ValueError(f"unknown synthetic route {route!r}; choose one of {ROUTES}")
    if duration_s is not None and not duration_s > 1.0:
        raise ValueError(f"duration_s must be > 1 s, got {duration_s!r}")
    ss = np.random.SeedSequence([int(seed), zlib.crc32(route.encode())])
    r_route, r_imu, r_speed, r_times, r_gps, r_drop = (
        np.random.default_rng(q) for q in ss.spawn(6)
    )
    segs = route_segments(route, r_route)
    yaw0 = float(r_route.uniform(-np.pi, np.pi))
    sim = simulate(segs, yaw0)
    while duration_s is not None and sim.t[-1] < duration_s:
        reps = int(np.ceil(duration_s / max(sim.t[-1], 1.0))) + 1
        sim = simulate(segs * reps, yaw0)
    n = sim.t.size if duration_s is None else int(np.searchsorted(sim.t, duration_s, "right"))
    t, x, y, yaw, v = sim.t[:n], sim.x[:n], sim.y[:n], sim.yaw[:n], sim.v[:n]
    yaw_rate, ax = sim.yaw_rate[:n], sim.ax[:n]
    truth = TruthStream(t, x, y, wrap_angle(yaw), v)

    imu = imu_stream(t, yaw, v, yaw_rate, ax, r_imu)
    speed = can_speed_stream(t, v, r_speed)
    gps, outages = gps_stream(t, x, y, yaw, v, r_times, r_gps, r_drop)

    segments = [sp for sp in sim.segments if sp[1] < t[-1]]
    if segments:
        segments[-1][2] = min(segments[-1][2], float(t[-1]))
    meta = DriveMeta(
        fix_source=FIXES_FROM_TRUTH,
        name=name or f"synthetic-{route}-s{seed}",
        source=f"synthetic:{route}:s{seed}",
        format="synthetic",
        epoch_s=EPOCH_S,
        origin_lat=ORIGIN_LAT,
        origin_lon=ORIGIN_LON,
        projection="enu",
        time_source="simulated",
        extra={
            "seed": int(seed),
            "route": route,
            "segments": segments,
            "gps_outages": [list(o) for o in outages],
        },
    )
    return Drive(meta=meta, gps=gps, imu=imu, speed=speed, truth=truth)


def default_drives(seed: int = 0) -> list[Drive]:
    """The built-in default data set: 4 drives (mixed, turns, roundabout, stop_and_go),
    60-120 s each, a few minutes in all."""
    return [generate_drive(seed=seed, route=r) for r in DEFAULT_ROUTES]
