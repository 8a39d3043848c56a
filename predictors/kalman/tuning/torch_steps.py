"""The differentiable Kalman filter of :mod:`posbench.predictors.kalman.tuning.gradient`, in torch.

The constant-acceleration filter of ``LinearKalman`` over a
:class:`~posbench.predictors.kalman.tuning.steps.Batch` of padded segments: one pass of a few
batched tensor operations per step for all segments at once, float64. Every function takes the
``torch`` module as its first argument (imported by the caller: torch is the ``train``
extra, never imported when predictors are built). Units: seconds, metres, radians, ENU.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from posbench.metrics.ca_model import ca_noise_entries, ca_noise_matrix, ca_transition_matrix
from posbench.predictors.kalman.inputs import HeadingInput
from posbench.predictors.kalman.tuning import steps as ks

if TYPE_CHECKING:
    import torch

#: beta of the beta-NLL (Seitzer et al. 2022), as the hybrid's training
BETA = 0.5
#: the kf's prior at its first fix (LinearKalman defaults) [m/s, m/s^2]
INIT_VEL_SIGMA, INIT_ACC_SIGMA = 15.0, 3.0
#: the parameter vector's entries (:func:`noise`)
THETA = ("a_q", "b_q", "c_q", "a_r", "b_r", "c_r", "log_sigma_a", "a_s", "b_s", "c_s")


class Noise(NamedTuple):
    """The filter's noise: ``Qc`` jerk density (2, 2) [m^2/s^5], ``R`` fix noise (2, 2)
    [m^2] (of a fix of weight 1), ``sa2`` IMU acceleration variance [m^2/s^4] per axis,
    ``slow2`` (2, 2) [m^2] the covariance of the receiver's slow error (added to the
    predicted covariance against a truth, never to a fix's weight)."""

    Qc: torch.Tensor
    R: torch.Tensor
    sa2: torch.Tensor
    slow2: torch.Tensor


def _chol(torch: Any, a: torch.Tensor, b: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
    """``L L'`` of ``L = [[exp a, 0], [c exp b, exp b]]`` (2x2)."""
    ea, eb = torch.exp(a), torch.exp(b)
    z = torch.zeros_like(ea)
    L = torch.stack([torch.stack([ea, z]), torch.stack([c * eb, eb])])
    return L @ L.T


def noise(torch: Any, theta: torch.Tensor, floors: torch.Tensor) -> Noise:
    """The :class:`Noise` of the parameter vector ``theta`` (:data:`THETA`: Cholesky
    log-diagonals and off-diagonal of Q_c and R, log sigma_a, those of the slow error), each held at
    ``floors`` from below (the kf's lower bounds)."""
    t = torch.maximum(theta, floors)
    return Noise(
        _chol(torch, t[0], t[1], t[2]),
        _chol(torch, t[3], t[4], t[5]),
        torch.exp(2 * t[6]),
        _chol(torch, t[7], t[8], t[9]),
    )


# -------------------------------------------------------------------------- filter
def _ca_blocks(dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F (..., 6, 6), white-jerk block per unit density (..., 3, 3)) over dt [s]
    (:mod:`posbench.metrics.ca_model`)."""
    f = ca_transition_matrix(dt)
    F = np.einsum("...ij,kl->...ikjl", f, np.eye(2)).reshape(dt.shape + (6, 6))
    return F, ca_noise_matrix(dt, 1.0)


class BatchTensors:
    """A :class:`~posbench.predictors.kalman.tuning.steps.Batch` as float64 tensors, with what does
    not depend on the parameters computed once: F and the white-jerk blocks per step, the
    position rows of F and the jerk weight of each scored fix's horizon; ``slow``: the
    predictions against a truth carry the receiver's slow error (:class:`Noise`)."""

    def __init__(self, torch: Any, bt: ks.Batch, slow: bool = False) -> None:
        def tens(a: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float64)

        self.bt = bt
        F, qb = _ca_blocks(bt.dt)
        self.F, self.qblk = tens(F), tens(qb)
        self.H, self.var = tens(bt.H), tens(bt.var)
        self.Z = _pad_z(torch, tens(bt.z))
        self.fix_w, self.acc_w = tens(bt.fix_w), tens(bt.acc_on.astype(float))
        self.x0, self.w0 = tens(bt.x0), tens(bt.w0)
        h = bt.ref_h
        Fh = np.zeros((h.size, 2, 6))
        Fh[:, 0, 0] = Fh[:, 1, 1] = 1.0
        Fh[:, 0, 2] = Fh[:, 1, 3] = h
        Fh[:, 0, 4] = Fh[:, 1, 5] = 0.5 * h * h
        self.Fh, self.qh = tens(Fh), tens(ca_noise_entries(h, 1.0)[0])
        self.ref, self.ref_w = tens(bt.ref), tens(bt.ref_w)
        #: 1 where the receiver's slow error counts (``slow`` and a truth reference), else 0
        self.truth_w = tens((slow & (bt.ref_w == 0.0)).astype(float))
        self.b = torch.as_tensor(bt.score_b)
        self.heading = bool(bt.need_heading.any())


def _pad(torch: Any, m: torch.Tensor, n: int) -> torch.Tensor:
    """2x2 ``m`` in the top-left corner of an n x n zero matrix."""
    return torch.nn.functional.pad(m, (0, n - 2, 0, n - 2))


class _Heading:
    """The heading of steps whose IMU states no yaw, from the filter itself, as
    ``LinearKalman._heading`` takes it: the velocity's direction
    above ``min_speed``, else the last heading advanced by the yaw rate (not differentiated:
    the kf uses it as a given). The last heading is the newer of the last one the IMU stated
    (from the steps, :func:`_last_known`) and the last one taken here."""

    def __init__(self, torch: Any, bt: ks.Batch, min_speed: float) -> None:
        self.torch, self.min_speed = torch, min_speed
        B = bt.size[1]

        def tens(a: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float64)

        #: steps where some segment needs a heading
        self.steps = np.flatnonzero(bt.need_heading.any(axis=1))
        self.need = torch.as_tensor(bt.need_heading)
        self.acc = torch.as_tensor(bt.acc_on)
        self.along = torch.as_tensor(bt.along)
        self.rate, self.t = tens(bt.yaw_rate), tens(bt.t)
        self.a = tens(np.nan_to_num(bt.a_veh))
        known_yaw, known_t = _last_known(bt)
        self.known_yaw, self.known_t = tens(known_yaw), tens(known_t)
        self.last = torch.full((B,), math.nan, dtype=torch.float64)
        self.last_t = torch.full((B,), -math.inf, dtype=torch.float64)

    def rows(self, k: int, m: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(dH (B, 4, 6), dz (B, 4)) to add to step k's rows (a step of :attr:`steps`)."""
        torch = self.torch
        need, t = self.need[k], self.t[k]
        with torch.no_grad():
            newer = self.known_t[k] > self.last_t
            last = torch.where(newer, self.known_yaw[k], self.last)
            last_t = torch.where(newer, self.known_t[k], self.last_t)
            vx, vy = m[:, 2].detach(), m[:, 3].detach()
            moving = torch.hypot(vx, vy) > self.min_speed
            course = torch.atan2(vy, vx)
            turned = last + self.rate[k] * (t - last_t)
            adv = torch.where(torch.isfinite(turned), turned, last)
            h_imu = torch.where(moving, course, adv)
            h_spd = torch.where(torch.isfinite(last), last, course)
            h_spd = torch.where(torch.isfinite(last) | moving, h_spd, torch.nan)
            h = torch.where(self.acc[k], h_imu, h_spd)
            ok = need & torch.isfinite(h)
            c = torch.where(ok, torch.cos(h), 0.0)
            s = torch.where(ok, torch.sin(h), 0.0)
            B = m.shape[0]
            dH = torch.zeros((B, ks.NZ, ks.NX), dtype=m.dtype)
            dz = torch.zeros((B, ks.NZ), dtype=m.dtype)
            acc = (ok & self.acc[k]).to(m.dtype)
            ax, ay = self.a[k, :, 0], self.a[k, :, 1]
            dH[:, 0, 4] = dH[:, 1, 5] = acc
            dz[:, 0] = acc * (c * ax - s * ay)
            dz[:, 1] = acc * (s * ax + c * ay)
            al = (ok & self.along[k]).to(m.dtype)
            dH[:, 2, 2], dH[:, 2, 3] = al * c, al * s
            taken = ok & self.acc[k]
            self.last = torch.where(taken, h, last)
            self.last_t = torch.where(taken, t, last_t)
        return dH, dz


def _last_known(bt: ks.Batch) -> tuple[np.ndarray, np.ndarray]:
    """Per step and segment, the newest heading the IMU stated at or before the step
    [rad] and its time [s] (NaN, -inf: none yet)."""
    T, B = bt.size
    known = np.isfinite(bt.yaw) & ~bt.need_heading & (bt.kind == ks.SENSOR)
    idx = np.where(known, np.arange(T)[:, None], -1)
    idx = np.maximum.accumulate(idx, axis=0)
    cols = np.arange(B)[None, :]
    has = idx >= 0
    yaw = np.where(has, bt.yaw[np.maximum(idx, 0), cols], np.nan)
    t = np.where(has, bt.t[np.maximum(idx, 0), cols], -np.inf)
    return yaw, t


def run_filter(
    torch: Any, bx: BatchTensors, noise: Noise, min_speed: float = HeadingInput().min_speed
) -> tuple[torch.Tensor, torch.Tensor]:
    """Filter every segment of ``bx``: the posterior (mean (N, 6), covariance (N, 6, 6))
    right after each scored fix (``score_k``, ``score_b`` of the batch), as the kf holds it
    when asked."""
    T, B = bx.bt.size
    Qc, R, sa2 = noise.Qc, noise.R, noise.sa2
    Q = torch.einsum("tbij,kl->tbikjl", bx.qblk, Qc).reshape(T, B, 6, 6)
    R4 = (
        bx.fix_w[..., None, None] * _pad(torch, R, ks.NZ)
        + bx.acc_w[..., None, None] * sa2 * _pad(torch, torch.eye(2, dtype=R.dtype), ks.NZ)
        + torch.diag_embed(bx.var)
    )
    init = torch.diag(
        torch.tensor([0.0, 0.0] + [INIT_VEL_SIGMA**2] * 2 + [INIT_ACC_SIGMA**2] * 2)
    ).to(R.dtype)
    P = bx.w0[:, None, None] * _pad(torch, R, ks.NX) + init
    m = torch.cat([bx.x0, torch.zeros((B, 4), dtype=R.dtype)], dim=1)
    # the state as one (B, 6, 7) array [P | m]: prediction and update move both in one
    # product each (the update: X -= (H P)' S^-1 (H X - [0 | z]))
    X = torch.cat([P, m[..., None]], dim=-1)
    heading = _Heading(torch, bx.bt, min_speed) if bx.heading else None
    turns = np.zeros(T, bool)
    if heading is not None:
        turns[heading.steps] = True
    wanted = np.zeros(T, bool)
    wanted[bx.bt.score_k] = True
    Fs, Qs, Rs, Hs = bx.F.unbind(0), Q.unbind(0), R4.unbind(0), bx.H.unbind(0)
    Zs = bx.Z.unbind(0)
    kept: list[torch.Tensor] = []
    at: dict[int, int] = {}
    for k in range(T):
        F = Fs[k]
        X = F @ X
        P = X[..., :6] @ F.mT + Qs[k]
        P = 0.5 * (P + P.mT)  # an asymmetric part would grow step by step
        X = torch.cat([P, X[..., 6:]], dim=-1)
        H, Z = Hs[k], Zs[k]
        if turns[k]:
            dH, dz = heading.rows(k, X[..., 6])  # type: ignore[union-attr]
            H, Z = H + dH, Z + _pad_z(torch, dz)
        HX = H @ X
        HP = HX[..., :6]
        S = HP @ H.mT + Rs[k]
        X = X - HP.mT @ torch.linalg.solve(S, HX - Z)
        if wanted[k]:
            at[k] = len(kept)
            kept.append(X)
    rows = torch.as_tensor([at[int(k)] for k in bx.bt.score_k])
    post = torch.stack(kept)[rows, bx.b]
    return post[..., 6], post[..., :6]


def _pad_z(torch: Any, z: torch.Tensor) -> torch.Tensor:
    """Measurements (..., 4) as the last column of a (..., 4, 7) zero array."""
    return torch.nn.functional.pad(z[..., None], (ks.NX, 0))


def predictions(torch: Any, bx: BatchTensors, noise: Noise) -> tuple[torch.Tensor, torch.Tensor]:
    """Per scored fix, the predicted position at its reference's horizon (mean (N, 2) [m],
    covariance (N, 2, 2) [m^2], ENU): the position block of ``F(h) P F(h)' + Q(h)``, plus
    the reference's own noise where it is a fix, or the receiver's slow error where it is
    a truth (which no filter of the fixes can remove)."""
    m, P = run_filter(torch, bx, noise)
    mean = (bx.Fh @ m[..., None])[..., 0]
    cov = (
        bx.Fh @ P @ bx.Fh.mT
        + bx.qh[:, None, None] * noise.Qc
        + bx.ref_w[:, None, None] * noise.R
        + bx.truth_w[:, None, None] * noise.slow2
    )
    return mean, cov


def losses(
    torch: Any, bx: BatchTensors, mean: torch.Tensor, cov: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per scored fix: (beta-NLL, NLL [nats], error [m]) of the reference under the
    predicted Gaussian: ``NLL = log(2 pi) + (log det S + e' S^-1 e) / 2`` and the beta-NLL
    ``det(S)^(beta / 2) NLL`` with the weight detached (Seitzer et al.: each fix's variance
    to the power beta; in 2-D its geometric-mean variance)."""
    e = bx.ref - mean
    a, b, d = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    det = a * d - b * b
    quad = (d * e[:, 0] ** 2 - 2 * b * e[:, 0] * e[:, 1] + a * e[:, 1] ** 2) / det
    nll = 0.5 * (torch.log(det) + quad) + math.log(2 * math.pi)
    w = det.detach() ** (BETA / 2)
    return w * nll, nll, torch.linalg.vector_norm(e.detach(), dim=1)
