"""The CTRA motion model (constant turn rate and acceleration) of
``CtraEkf``: pure maths on floats and numpy buffers.

State: :data:`IX` ... :data:`IA` index the motion block ``[x, y, yaw, v, yaw_rate, a]``: ENU
position [m], heading [rad, ENU], speed along the heading [m/s], yaw rate [rad/s],
longitudinal acceleration [m/s^2]; :data:`IBA` ... :data:`IKV` the filter's sensor states
(accelerometer bias, gyro bias, IMU yaw offset, wheel-speed scale error).

Prediction over T seconds uses the CTRA closed form written as a rotation of the
body-frame displacement ``D = int_0^T (v + a s) (cos w s, sin w s) ds``, built from six
integrals ``C_n = int s^n cos(w s) ds``, ``S_n = int s^n sin(w s) ds`` (n = 0..2). For
``|w T| < 0.05`` they come from their Taylor series (exact to ~1e-11 relative), so the
straight-line limit (constant acceleration) has no 1/w or 1/w^2 blow-up; the analytic
Jacobian reuses the same integrals (dD/dv = (C0, S0), dD/da = (C1, S1),
dD/dw = (-(v S1 + a S2), v C1 + a C2), dp/dyaw = rotation of the displacement).

Process noise: white jerk (``jerk_psd`` [m^2/s^5]) on the (position-along-heading, v, a)
chain, white yaw acceleration (``yaw_acc_psd`` [rad^2/s^3]) on (yaw, yaw_rate), and a
small position random walk (``pos_psd`` [m^2/s]) for what CTRA does not model (slip,
lane changes at constant yaw rate, GNSS wander).

The scalar functions are kernels (:func:`~posbench.predictors._kernels.kernel`): the ekf's
rows (:mod:`~posbench.predictors.kalman.ctra_rows`) call them compiled; from Python they
run compiled too, after numba's first load.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._geometry import wrap_angle
from posbench.predictors._kernels import kernel

SERIES_LIMIT = 0.05  # |w T| below which the integrals use their Taylor series
IX, IY, IYAW, IV, IW, IA, IBA, IBW, IBY, IKV = range(10)
N_STATE = 10


@kernel
def ctra_integrals(w: float, T: float) -> tuple[float, float, float, float, float, float]:
    """(C0, S0, C1, S1, C2, S2) with C_n = int_0^T s^n cos(w s) ds, S_n likewise with sin.

    Stable for any w: the closed forms for |w T| >= 0.05, Taylor series below.
    """
    p = w * T
    if abs(p) < SERIES_LIMIT:
        T2 = T * T
        p2 = p * p
        p4 = p2 * p2
        # C_n = T^(n+1) sum_k (-1)^k p^(2k) / ((2k)! (n+2k+1))
        # S_n = T^(n+1) sum_k (-1)^k p^(2k+1) / ((2k+1)! (n+2k+2))
        C0 = T * (1.0 - p2 / 6.0 + p4 / 120.0)
        S0 = T * (p / 2.0 - p * p2 / 24.0 + p * p4 / 720.0)
        C1 = T2 * (0.5 - p2 / 8.0 + p4 / 144.0)
        S1 = T2 * (p / 3.0 - p * p2 / 30.0 + p * p4 / 840.0)
        C2 = T2 * T * (1.0 / 3.0 - p2 / 10.0 + p4 / 168.0)
        S2 = T2 * T * (p / 4.0 - p * p2 / 36.0 + p * p4 / 960.0)
        return C0, S0, C1, S1, C2, S2
    s = math.sin(p)
    c = math.cos(p)
    iw = 1.0 / w
    iw2 = iw * iw
    C0 = s * iw
    S0 = (1.0 - c) * iw
    C1 = T * s * iw + (c - 1.0) * iw2
    S1 = -T * c * iw + s * iw2
    C2 = T * T * s * iw - 2.0 * iw * S1
    S2 = -T * T * c * iw + 2.0 * iw * C1
    return C0, S0, C1, S1, C2, S2


@kernel
def ctra_displacement(yaw: float, v: float, w: float, a: float, T: float) -> tuple[float, float]:
    """ENU displacement [m] over T [s] under CTRA from heading yaw, speed v, yaw rate w, accel a."""
    C0, S0, C1, S1, _, _ = ctra_integrals(w, T)
    dxb = v * C0 + a * C1
    dyb = v * S0 + a * S1
    c = math.cos(yaw)
    s = math.sin(yaw)
    return c * dxb - s * dyb, s * dxb + c * dyb


_FLAT: dict[tuple[str, int], np.ndarray] = {}


def _flat(what: str, ncols: int) -> np.ndarray:
    """Flat (C order) indices in a matrix of ``ncols`` columns of the entries ``ctra_step``
    ("jac") or ``ctra_process_noise`` ("q") write, in the order they write them."""
    key = (what, ncols)
    if key not in _FLAT:
        rc = _JAC_ENTRIES if what == "jac" else Q_ENTRIES
        _FLAT[key] = np.array([r * ncols + c for r, c in rc])
    return _FLAT[key]


_JAC_ENTRIES = ((0, 2), (1, 2), (0, 3), (1, 3), (0, 4), (1, 4), (0, 5), (1, 5), (2, 4), (3, 5))


@kernel
def ctra_motion(yaw: float, v: float, w: float, a: float, T: float) -> tuple:
    """The CTRA step over T [s] from heading ``yaw`` [rad], speed ``v`` [m/s], yaw rate ``w``
    [rad/s] and acceleration ``a`` [m/s^2]: ``(dx, dy, f02, f03, f04, f05, f12, f13, f14,
    f15, c, s)``, the ENU displacement [m], the Jacobian's entries of the position rows
    (F[0, 2..5], F[1, 2..5]; F[2, 4] = F[3, 5] = T and the identity elsewhere) and the
    cosine and sine of ``yaw``."""
    C0, S0, C1, S1, C2, S2 = ctra_integrals(w, T)
    dxb = v * C0 + a * C1
    dyb = v * S0 + a * S1
    c = math.cos(yaw)
    s = math.sin(yaw)
    dx = c * dxb - s * dyb
    dy = s * dxb + c * dyb
    ddxb_dw = -(v * S1 + a * S2)
    ddyb_dw = v * C1 + a * C2
    f04 = c * ddxb_dw - s * ddyb_dw
    f14 = s * ddxb_dw + c * ddyb_dw
    f03, f13 = c * C0 - s * S0, s * C0 + c * S0
    f05, f15 = c * C1 - s * S1, s * C1 + c * S1
    return dx, dy, -dy, f03, f04, f05, dx, f13, f14, f15, c, s


def ctra_step(x: np.ndarray, T: float, F: np.ndarray) -> None:
    """Advance the state x (first 6 entries) by T [s] in place; write the Jacobian into F
    (:func:`ctra_motion`).

    F (C order, at least 6x6) must hold the identity outside rows 0-3's model entries (it is
    fully rewritten there).
    """
    px, py, yaw, v, w, a = x[: IA + 1].tolist()
    dx, dy, f02, f03, f04, f05, f12, f13, f14, f15, _, _ = ctra_motion(yaw, v, w, a, T)
    # F[0, 2], F[1, 2], F[0, 3], F[1, 3], F[0, 4], F[1, 4], F[0, 5], F[1, 5], F[2, 4], F[3, 5]
    F.put(_flat("jac", F.shape[1]), (f02, f12, f03, f13, f04, f14, f05, f15, T, T))
    x[:IW] = (px + dx, py + dy, wrap_angle(yaw + w * T), v + a * T)


Q_ENTRIES = (
    (0, 0),
    (1, 1),
    (0, 1),
    (1, 0),
    (0, 3),
    (3, 0),
    (1, 3),
    (3, 1),
    (0, 5),
    (5, 0),
    (1, 5),
    (5, 1),
    (3, 3),
    (3, 5),
    (5, 3),
    (5, 5),
    (2, 2),
    (2, 4),
    (4, 2),
    (4, 4),
)


@kernel
def ctra_noise_entries(
    c: float, s: float, T: float, jerk_psd: float, yaw_acc_psd: float, pos_psd: float
) -> tuple:
    """The process noise's entries over T [s] at a heading of cosine ``c`` and sine ``s``,
    in the order of :data:`Q_ENTRIES` (white jerk along the heading, white yaw
    acceleration, a position random walk; module docstring)."""
    T2 = T * T
    T3 = T2 * T
    qj = jerk_psd
    pp = qj * T3 * T2 / 20.0  # along-heading position
    pv = qj * T2 * T2 / 8.0
    pa = qj * T3 / 6.0
    pcs = pp * c * s
    pvc, pvs, pac, pas = pv * c, pv * s, pa * c, pa * s
    q_va = qj * T2 / 2.0
    qw = yaw_acc_psd
    q_yw = qw * T2 / 2.0
    return (
        pp * c * c + pos_psd * T,
        pp * s * s + pos_psd * T,  # (0,0), (1,1)
        pcs,
        pcs,
        pvc,
        pvc,
        pvs,
        pvs,
        pac,
        pac,
        pas,
        pas,  # (0|1, 1|3|5), sym.
        qj * T3 / 3.0,
        q_va,
        q_va,
        qj * T,  # (3,3), (3,5), (5,3), (5,5)
        qw * T3 / 3.0,
        q_yw,
        q_yw,
        qw * T,  # (2,2), (2,4), (4,2), (4,4)
    )


def ctra_process_noise(
    yaw: float, T: float, jerk_psd: float, yaw_acc_psd: float, pos_psd: float, out: np.ndarray
) -> np.ndarray:
    """Write the process noise over T [s] at heading yaw into the motion block (6x6) of
    ``out`` (C order, at least 6x6; its other entries are left as they are: zeros in a
    Q buffer)."""
    q = ctra_noise_entries(math.cos(yaw), math.sin(yaw), T, jerk_psd, yaw_acc_psd, pos_psd)
    out.put(_flat("q", out.shape[1]), q)
    return out
