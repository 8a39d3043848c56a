"""The training corpus's routes: per profile, random manoeuvre blocks for the kinematic
simulator (:func:`posbench.scenarios.synthetic_motion.simulate`), and the vehicle limits drawn per
drive that they are driven with.

Per profile (speed targets in :data:`PROFILE_SPEEDS_MPS`):

- ``urban`` (3-16 m/s): turns (radius 8-60 m, 30-120 deg), roundabouts (ring radius
  8-40 m), lane changes, U-turns (180 deg at radius 6-12 m, 2.5-5 m/s), traffic-light stops
  and stop-and-go (dwell 1-30 s, log-uniform, creeping at 0.5-2 m/s between stops);
- ``rural`` (10-27 m/s): turns (radius 30-300 m), junction turns (8-20 m), curves
  (300-1000 m), roundabouts (15-40 m), overtaking lane changes, junction stops, rare U-turns;
- ``highway`` (22-40 m/s): from a standstill up an on-ramp (radius 50-150 m), then gentle
  curves (radius 300-2000 m, 3-30 deg), lane changes, long straights, rare jams.

A lane change is two opposite arcs moving the car 3.5 m sideways over 30-120 m
(``theta = 2 atan(3.5 / L)``, ``R = L / (2 sin theta)``).

Per drive, the vehicle's limits are drawn (:class:`VehicleLimits`: acceleration
1-3.5 m/s^2, braking 1.5-6 m/s^2, lateral acceleration 2-5 m/s^2, speed smoothing
0.8-1.6 s bounding the jerk, curvature smoothing 4-10 m). Each segment carries the scenario
label the labeller (:mod:`posbench.scenarios.labels`) would give it and its finer manoeuvre
kind (:data:`MANOEUVRES`). Lengths and radii in metres, speeds in m/s, angles in degrees.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from posbench.scenarios.labels import LabelThresholds
from posbench.scenarios.synthetic import roundabout
from posbench.scenarios.synthetic_motion import Segment, stop, straight

#: the finer manoeuvre kinds of ``meta.extra["manoeuvres"]``
MANOEUVRES = (
    "straight",
    "turn",
    "curve",
    "roundabout",
    "lane_change",
    "u_turn",
    "start_stop",
    "creep",
)
#: speed targets [m/s] of each profile's straights
PROFILE_SPEEDS_MPS: dict[str, tuple[float, float]] = {
    "urban": (3.0, 16.0),
    "rural": (10.0, 27.0),
    "highway": (22.0, 40.0),
}
LANE_WIDTH_M = 3.5
_TURN_YAW_RATE = LabelThresholds().turn_yaw_rate_rps
_TURN_RADIUS_M = 1.0 / LabelThresholds().turn_curvature_inv_m
_ROUNDABOUT_RADIUS_M = LabelThresholds().roundabout_radius_m


@dataclass(frozen=True)
class VehicleLimits:
    """One drive's vehicle: ``a_acc`` acceleration, ``a_dec`` braking, ``ay_max`` lateral
    acceleration [m/s^2], ``v_smooth_s`` speed smoothing [s], ``kappa_smooth_m`` curvature
    smoothing [m] (the keyword limits of :func:`posbench.scenarios.synthetic_motion.simulate`)."""

    a_acc: float
    a_dec: float
    ay_max: float
    v_smooth_s: float
    kappa_smooth_m: float


def loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A draw uniform in log between ``lo`` and ``hi`` (> 0)."""
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_limits(rng: np.random.Generator) -> VehicleLimits:
    """A vehicle's limits, uniform in the ranges of the module doc."""
    return VehicleLimits(
        a_acc=float(rng.uniform(1.0, 3.5)),
        a_dec=float(rng.uniform(1.5, 6.0)),
        ay_max=float(rng.uniform(2.0, 5.0)),
        v_smooth_s=float(rng.uniform(0.8, 1.6)),
        kappa_smooth_m=float(rng.uniform(4.0, 10.0)),
    )


def _arc_label(radius_m: float, speed_mps: float, ay_max: float) -> str:
    """``turn`` where the labeller would see one (yaw rate above its threshold at the speed
    the car can take the arc, or a tight radius), else ``straight``."""
    v = min(speed_mps, math.sqrt(ay_max * radius_m))
    return "turn" if (v / radius_m > _TURN_YAW_RATE or radius_m < _TURN_RADIUS_M) else "straight"


def _arc(
    angle_deg: float,
    radius_m: float,
    speed_mps: float,
    label: str,
    manoeuvre: str,
    cont: bool = False,
) -> Segment:
    return Segment(
        "arc",
        angle_rad=math.radians(angle_deg),
        radius_m=radius_m,
        speed_mps=speed_mps,
        label=label,
        manoeuvre=manoeuvre,
        cont=cont,
    )


def lane_change(length_m: float, speed_mps: float, side: float) -> list[Segment]:
    """Two opposite arcs moving the car :data:`LANE_WIDTH_M` to the left (``side`` = +1) or
    right (-1) over ``length_m`` [m] along the road."""
    theta = 2.0 * math.atan(LANE_WIDTH_M / length_m)
    radius = length_m / (2.0 * math.sin(theta))
    deg = math.degrees(theta) * side
    # labelled straight: the two arcs are too short and gentle for the labeller's turn
    return [
        _arc(deg, radius, speed_mps, "straight", "lane_change"),
        _arc(-deg, radius, speed_mps, "straight", "lane_change", cont=True),
    ]


class ProfileRoute:
    """Draws one profile's manoeuvre blocks from a seeded generator."""

    def __init__(self, profile: str, rng: np.random.Generator, lim: VehicleLimits) -> None:
        self.profile, self.rng, self.lim = profile, rng, lim
        self.v_lo, self.v_hi = PROFILE_SPEEDS_MPS[profile]

    def u(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def side(self) -> float:
        return 1.0 if self.rng.random() < 0.5 else -1.0

    def speed(self) -> float:
        return self.u(self.v_lo, self.v_hi)

    def turn(
        self, r_lo: float, r_hi: float, a_lo: float, a_hi: float, v: float, kind: str = "turn"
    ) -> list[Segment]:
        r = self.u(r_lo, r_hi)
        return [
            _arc(self.side() * self.u(a_lo, a_hi), r, v, _arc_label(r, v, self.lim.ay_max), kind)
        ]

    def roundabout(self, r_lo: float, r_hi: float) -> list[Segment]:
        r = self.u(r_lo, r_hi)
        # the labeller calls a ring of radius >= its roundabout_radius_m (30 m) a turn
        lab = "roundabout" if r < _ROUNDABOUT_RADIUS_M else "turn"
        return [
            replace(g, label=lab, manoeuvre="roundabout")
            for g in roundabout(self.rng, self.u, radius_m=r, speed_mps=self.u(5.0, 10.0))
        ]

    def u_turn(self) -> list[Segment]:
        r, v = self.u(6.0, 12.0), self.u(2.5, 5.0)
        return [straight(self.u(15, 30), v), _arc(self.side() * 180.0, r, v, "turn", "u_turn")]

    def stop_and_go(self, v_hi: float) -> list[Segment]:
        out: list[Segment] = []
        for _ in range(int(self.rng.integers(1, 5))):
            out += [
                straight(self.u(10, 60), self.u(3.0, v_hi)),
                stop(loguniform(self.rng, 1.0, 30.0)),
            ]
            if self.rng.random() < 0.5:  # creep up the queue and stop again
                out += [
                    Segment(
                        "straight",
                        length_m=self.u(2, 15),
                        speed_mps=self.u(0.5, 2.0),
                        label="straight",
                        manoeuvre="creep",
                    ),
                    stop(loguniform(self.rng, 1.0, 10.0)),
                ]
        return out

    def lane_change(self, l_lo: float, l_hi: float, v: float) -> list[Segment]:
        return lane_change(self.u(l_lo, l_hi), v, self.side())

    def block(self) -> list[Segment]:
        """A straight lead-in and one manoeuvre, drawn with the profile's weights."""
        v = self.speed()
        if self.profile == "urban":
            lead = straight(self.u(30, 250), v)
            opts: dict[str, Callable[[], list[Segment]]] = {
                "straight": lambda: [straight(self.u(50, 300), self.speed())],
                "turn": lambda: self.turn(8, 60, 30, 120, self.u(3.0, 12.0)),
                "roundabout": lambda: self.roundabout(8, 40),
                "lane_change": lambda: self.lane_change(30, 80, v),
                "u_turn": self.u_turn,
                "stop_and_go": lambda: self.stop_and_go(8.0),
                "stop": lambda: [stop(loguniform(self.rng, 1.0, 30.0))],
            }
            w = {
                "straight": 0.15,
                "turn": 0.25,
                "roundabout": 0.12,
                "lane_change": 0.15,
                "u_turn": 0.06,
                "stop_and_go": 0.12,
                "stop": 0.15,
            }
        elif self.profile == "rural":
            lead = straight(self.u(100, 800), v)
            opts = {
                "straight": lambda: [straight(self.u(200, 1000), self.speed())],
                "turn": lambda: self.turn(30, 300, 15, 90, v),
                "junction": lambda: self.turn(8, 20, 80, 100, self.u(5.0, 8.0)),
                "curve": lambda: self.turn(300, 1000, 5, 30, v, "curve"),
                "roundabout": lambda: self.roundabout(15, 40),
                "lane_change": lambda: self.lane_change(60, 120, v),
                "stop": lambda: [
                    straight(self.u(30, 60), self.u(5.0, 10.0)),
                    stop(loguniform(self.rng, 1.0, 15.0)),
                ],
                "u_turn": self.u_turn,
                "stop_and_go": lambda: self.stop_and_go(10.0),
            }
            w = {
                "straight": 0.13,
                "turn": 0.2,
                "junction": 0.08,
                "curve": 0.2,
                "roundabout": 0.1,
                "lane_change": 0.15,
                "stop": 0.07,
                "u_turn": 0.04,
                "stop_and_go": 0.03,
            }
        else:
            lead = straight(self.u(300, 2000), v)
            opts = {
                "straight": lambda: [straight(self.u(500, 3000), self.speed())],
                "curve": lambda: self.turn(300, 2000, 3, 30, v, "curve"),
                "lane_change": lambda: self.lane_change(60, 120, v),
                "stop_and_go": lambda: self.stop_and_go(8.0),
            }
            w = {"straight": 0.3, "curve": 0.4, "lane_change": 0.25, "stop_and_go": 0.05}
        keys = list(w)
        p = np.array([w[k] for k in keys])
        pick = keys[int(self.rng.choice(len(keys), p=p / p.sum()))]
        return [lead, *opts[pick]()]

    def start(self) -> list[Segment]:
        """A standstill, and for the highway an on-ramp."""
        out = [stop(self.u(1.0, 5.0))]
        if self.profile == "highway":
            out += [
                straight(self.u(20, 60), self.u(8.0, 12.0)),
                *self.turn(50, 150, 60, 120, self.u(10.0, 16.0)),
            ]
        return out
