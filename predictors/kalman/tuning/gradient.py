"""Fit a Kalman filter's noise by gradient descent on development drives (OKF).

The recipe of Greenberg, Yannay and Mannor, "Optimization or Architecture: How to Hack
Kalman Filtering" (NeurIPS 2023): keep the filter's architecture, treat its noise
matrices as parameters and fit them by gradient descent on the filter's own predictions,
instead of deriving them from assumptions about the noise (or searching a grid).

**The filter** is the constant-acceleration model of
``LinearKalman`` (``ca_filter``),
differentiable in torch (:mod:`~posbench.predictors.kalman.tuning.torch_steps`): state ``[x, y, vx,
vy, ax, ay]`` (m, m/s, m/s^2, local ENU), ``F(dt) = f(dt) (x) I2`` with the per-axis
``f = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]``, white jerk ``Q(dt) = q(dt) (x) Q_c`` with
the per-axis white-jerk block ``q(dt)`` and a 2x2 jerk density ``Q_c`` [m^2/s^5] (x and y
may differ and correlate; LinearKalman's ``jerk_psd`` is ``Q_c = jerk_psd I2``). Updates at
the drive's own (irregular) fix times with fix noise ``R`` [m^2] (2x2; a fix stating an
accuracy ``s`` is weighed ``(s / sigma_ref)^2 R``), the IMU's vehicle-frame acceleration
rotated to ENU with its yaw (else the filter's heading, as LinearKalman) as a measurement
of ``(ax, ay)`` with noise ``sigma_a^2 I2`` [m^2/s^4], and the wheel speed along the heading
with the kf's fixed speed noise (:class:`~posbench.predictors.kalman.inputs.SpeedInput`),
all in the runner's order (:mod:`~posbench.predictors.kalman.tuning.steps`). With the same noise it
gives LinearKalman's answers (default inputs: no bias estimate, gate or adapted noise) to
rounding. The kf bank's robust extras (accelerometer bias estimate, adapted IMU noise,
gates, the fixes' own noise estimate) are not part of it: it is the plain linear filter
those options start from.

**The parameters**, as OKF does, through Cholesky factors so that every step keeps them
positive definite: ``Q_c = L_q L_q'`` and ``R = L_r L_r'`` with ``L = [[exp a, 0], [c exp b,
exp b]]`` (log-diagonal ``a, b`` and a dimensionless off-diagonal ``c``); ``log sigma_a``;
and, optionally (``slow``), a 2x2 covariance of the receiver's *slow* error (its Cholesky
factor the same way): against a truth, a receiver whose error wanders over minutes
(``consumer``: 1 m with a 45 s time constant) leaves an offset no filter of its fixes can
remove, so the predicted covariance against a truth becomes ``P + S_slow`` (a consider
term, as :class:`~posbench.predictors.kalman.gnss_noise.GnssNoise` adds one); it never weighs a
fix. Without it the fit inflates ``q`` and ``R`` to explain that offset (``consumer``, 4
synthetic drives: q ~ 700-15000 m^2/s^5, mean error up 6 %). It is off by default: for a
white receiver it is only weakly identifiable beside ``R`` (at the 0.2 s horizon both
mostly add variance) and drifts away from 0, biasing ``R`` and ``sigma_a`` low. Against a
receiver's own fixes it cancels (reference and fixes share it) and is not used.

**The loss** is the one the learned ``hybrid`` network trains with: beta-NLL (Seitzer et
al., ICLR 2022, beta 0.5) of the reference position at ``t_fix + 0.2 s`` under the filter's
predicted Gaussian (mean ``F(0.2) m``, covariance the position block of
``F(0.2) P F(0.2)' + Q(0.2)``, asked right after each fix as the runner asks), averaged
over the scored fixes after each segment's burn-in; the 2-D form weighs each fix's NLL by
the detached ``det(S)^(beta / 2)``. The reference is the drive's truth where it has one,
else the later fix of its own nearest ``t_fix + 0.2 s`` (its noise ``R`` then adds to the
covariance: unlike the hybrid's centred cubic, a later fix's noise is independent of
what the filter has seen, so this likelihood is exact under the model). The mean error
[m] at that horizon is reported beside it.

**Why the NLL and not the error alone**: the filter's mean depends only on the *ratios*
of ``Q_c``, ``R`` and ``sigma_a^2`` (scale them all by k and the gains do not change), so
an error loss cannot tell ``q`` from ``2 q`` with ``2 R``. The covariance does scale with
them, and the NLL of the reference under it makes the scale identifiable: the fitted
``q``, ``R`` and ``sigma_a`` are the noise the data show, not only their ratios.

**The kf's options** (:func:`kf_options`): ``jerk_psd`` = the mean eigenvalue of ``Q_c``
(the kf's Q is isotropic), ``gps_sigma`` = sqrt(mean eigenvalue of ``R``) where fixes state
no accuracy, ``gps_sigma_scale`` = that sigma / the stated sigma where they do,
``accel_sigma`` = ``sigma_a``.

Batched: drives are cut into overlapping segments, padded to a common length and stacked
(:func:`~posbench.predictors.kalman.tuning.steps.batch`), so an iteration is a few tensor
operations per step over all segments at once. Adam, full batch, float64, one thread:
seeded and deterministic. Optional early stop on held-out segments' NLL.

Torch is imported inside the functions (the ``train`` extra), never when predictors are
built. Units: seconds, metres, radians, local ENU.
"""

from __future__ import annotations

import math
import time
import zlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from posbench.predictors.kalman.inputs import SpeedInput
from posbench.predictors.kalman.tuning import steps as ks
from posbench.scenarios.drive import Drive, GpsStream

#: what to install when torch is missing
TRAIN_EXTRA = "install the train extra: pip install 'posbench-harness[train]'"
#: the kf's options' ranges (LinearKalman / GnssInput / AccelInput checks)
RANGES = {
    "jerk_psd": (1e-9, 1e6),
    "gps_sigma": (1e-4, 1e3),
    "gps_sigma_scale": (1e-3, 1e3),
    "accel_sigma": (1e-4, 1e3),
}
#: the floor of sigma_slow [m]
SLOW_FLOOR_M = 1e-4
#: defaults of :func:`gradient_tune`
ITERATIONS, LR = 100, 0.1


def require_torch() -> Any:
    """The ``torch`` module, or ImportError saying to install the ``train`` extra."""
    try:
        import torch
    except ImportError:
        raise ImportError(f"gradient tuning needs PyTorch: {TRAIN_EXTRA}") from None
    return torch


def sigma_reference(gps: Sequence[GpsStream]) -> float | None:
    """The per-axis 1-sigma [m] the fitted fix noise is stated relative to: the median
    accuracy the fixes state (finite, > 0), None when none states one."""
    acc = [
        g.accuracy[np.isfinite(g.accuracy) & (g.accuracy > 0)]
        for g in gps
        if g.accuracy is not None
    ]
    a = np.concatenate(acc) if acc else np.zeros(0)
    return float(np.median(a)) if a.size else None


def drive_fixes(drives: Sequence[Drive], gps_profile: str, seed: int = 0) -> list[GpsStream]:
    """The fixes to tune on: each drive's own for ``native`` or without truth, else drawn
    from its truth under the simulated profile (:func:`posbench.scenarios.degrade.degrade_gps`,
    a seed per drive from ``seed`` and its name)."""
    from posbench.scenarios.degrade import degrade_gps

    out = []
    for d in drives:
        if gps_profile == "native" or d.truth is None or len(d.truth) < 2:
            out.append(d.gps)
        else:
            s = (seed * 1_000_003 + zlib.crc32(d.name.encode())) % 2**32
            out.append(degrade_gps(d.truth, gps_profile, seed=s))
    return out


def kf_options(
    Qc: np.ndarray,
    R: np.ndarray,
    sigma_a: float | None,
    sigma_ref: float | None,
    unstated: bool = True,
    clamped: dict[str, float] | None = None,
) -> dict[str, float]:
    """The kf's flat options of fitted noise (module docstring): ``jerk_psd`` [m^2/s^5] =
    trace(Q_c) / 2; the fix sigma ``sqrt(trace(R) / 2)`` [m] as ``gps_sigma_scale`` (that
    sigma / ``sigma_ref``) where fixes state an accuracy (``sigma_ref`` given) and as
    ``gps_sigma`` where some state none (``unstated``, or no ``sigma_ref``);
    ``accel_sigma`` = ``sigma_a`` [m/s^2] (None: not fitted). Rounded to 4 significant
    digits, held in the kf's ranges (:data:`RANGES`); ``clamped`` (given) receives the
    fitted value of each option that lay outside its range. A NaN stays NaN (the run
    refuses it)."""

    def put(name: str, v: float) -> float:
        lo, hi = RANGES[name]
        if clamped is not None and not lo <= v <= hi and v == v:
            clamped[name] = v
        return float(f"{min(max(v, lo), hi):.4g}") if v == v else v

    sig = math.sqrt(0.5 * float(np.trace(R)))
    out = {"jerk_psd": put("jerk_psd", 0.5 * float(np.trace(Qc)))}
    if sigma_ref:
        out["gps_sigma_scale"] = put("gps_sigma_scale", sig / sigma_ref)
    if unstated or not sigma_ref:
        out["gps_sigma"] = put("gps_sigma", sig)
    if sigma_a is not None:
        out["accel_sigma"] = put("accel_sigma", sigma_a)
    return out


def gradient_tune(
    drives: Sequence[Drive],
    gps_profile: str,
    *,
    gps: Sequence[GpsStream] | None = None,
    seed: int = 0,
    iterations: int = ITERATIONS,
    lr: float = LR,
    holdout: float = 0.0,
    patience: int = 20,
    segment_s: float = 10.0,
    burn_in_s: float = 2.0,
    use_imu: bool = True,
    speed: SpeedInput | None = ks.KF_SPEED,
    slow: bool = False,
    init: dict[str, float] | None = None,
    on_step: Callable[[int, dict[str, float]], None] | None = None,
) -> dict[str, Any]:
    """Fit the kf's noise on ``drives`` by gradient descent (module docstring).

    Args:
        drives: development drives (never evaluation drives).
        gps_profile: ``none``, ``rtk``, ``consumer`` (fixes drawn from each drive's truth,
            :func:`drive_fixes`) or ``native`` (the drives' own fixes).
        gps: the fixes to use instead, one stream per drive (e.g. those the replay feeds).
        seed: seeds the fixes drawn and the held-out split; the fit itself is deterministic.
        iterations: Adam steps (full batch). lr: Adam's learning rate (the parameters are
            logs and a dimensionless off-diagonal: 0.1 moves a noise ~10 % per step).
        holdout: fraction of the segments held out; > 0: keep the parameters of the best
            held-out NLL and stop after ``patience`` steps without improvement.
        segment_s, burn_in_s: scored length [s] of a segment and the burn-in [s] before it
            (:func:`~posbench.predictors.kalman.tuning.steps.segment`); segment_s <= 0: whole
            drives.
        use_imu: fit with the IMU's acceleration (and its noise sigma_a); False: fixes (and
            speed) only. speed: the wheel speed's fixed noise; None: no speed updates.
        slow: fit the receiver's slow error too (module docstring: for receivers whose error
            wanders, against a truth).
        init: starting values ``q`` [m^2/s^5], ``sigma_fix`` [m] (of a fix stating
            ``sigma_ref``, or stating none), ``sigma_a`` [m/s^2], ``sigma_slow`` [m] per axis;
            default the kf's own (2, the stated sigma or 0.3, 0.3) and sigma_fix.
        on_step: called after each step with its number (from 1) and the training figures
            before it (``beta_nll``, ``nll`` [nats], ``error_m``, ``q``, ``sigma_fix_m``,
            ``sigma_a`` with the IMU, ``sigma_slow_m`` with ``slow``).

    Returns:
        ``params`` (the kf's flat options, :func:`kf_options`); ``clamped`` (the fitted
        value of each option that lay outside the kf's range, held in it); the fitted ``Q_c``
        [m^2/s^5], ``R`` [m^2] (of a fix stating ``sigma_ref_m``, or none), ``sigma_a``
        [m/s^2] (None without IMU) and ``slow`` (2, 2) [m^2] (None unless fitted);
        ``loss`` (``train`` and, with ``holdout``, ``holdout``: mean beta-NLL, NLL [nats]
        and error [m] at the 0.2 s horizon); ``iterations`` run, ``best_iteration`` (the
        parameters returned: after that many steps), ``segments``, ``fixes`` (scored),
        ``seconds``, ``history`` (the training figures per step).

    Raises:
        ImportError: torch is missing (:data:`TRAIN_EXTRA`).
        ValueError: no drive has a fix to fit on.
    """
    torch = require_torch()
    from posbench.predictors.kalman.tuning import torch_steps as kt

    t_start = time.perf_counter()
    fixes = list(gps) if gps is not None else drive_fixes(drives, gps_profile, seed)
    sigma_ref = sigma_reference(fixes)
    unstated = any(
        g.accuracy is None or not (np.isfinite(g.accuracy) & (g.accuracy > 0)).all()
        for g in fixes
        if len(g)
    )
    steps = [
        ks.drive_steps(d, g, sigma_ref, use_imu=use_imu, speed=speed)
        for d, g in zip(drives, fixes, strict=True)
    ]
    bt = ks.batch(steps, segment_s, burn_in_s)
    if bt is None:
        raise ValueError("no drive has a fix to fit on (each needs fixes past its burn-in)")
    B = bt.size[1]
    n_hold = min(B - 1, max(1, round(holdout * B))) if holdout > 0.0 and B > 1 else 0
    held = np.zeros(B, bool)
    held[np.random.default_rng(seed).permutation(B)[:n_hold]] = True
    start = {"q": 2.0, "sigma_fix": sigma_ref or 0.3, "sigma_a": 0.3, **(init or {})}
    start.setdefault("sigma_slow", start["sigma_fix"])
    r_floor = RANGES["gps_sigma"][0] if sigma_ref is None else 1e-3 * sigma_ref
    lq, lr0 = 0.5 * math.log(start["q"]), math.log(start["sigma_fix"])
    theta0 = [lq, lq, 0.0, lr0, lr0, 0.0, math.log(start["sigma_a"])]
    ls = math.log(max(start["sigma_slow"], 2 * SLOW_FLOOR_M))
    theta0 += [ls, ls, 0.0]
    floor = [0.5 * math.log(RANGES["jerk_psd"][0])] * 2 + [-math.inf]
    floor += [math.log(r_floor)] * 2 + [-math.inf]
    floor += [math.log(RANGES["accel_sigma"][0])] + [math.log(SLOW_FLOOR_M)] * 2 + [-math.inf]
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny matrices: threads only add overhead
    try:
        bx = kt.BatchTensors(torch, bt, slow=slow)
        test = torch.as_tensor(held[bt.score_b])
        train = ~test
        theta = torch.tensor(theta0, dtype=torch.float64, requires_grad=True)
        floors = torch.tensor(floor, dtype=torch.float64)
        opt = torch.optim.Adam([theta], lr=lr)
        history: list[dict[str, float]] = []
        best: tuple[float, int, Any, dict[str, float], dict[str, float]]
        best = (math.inf, 0, theta.detach().clone(), {}, {})
        for it in range(iterations + 1):
            opt.zero_grad()
            nz = kt.noise(torch, theta, floors)
            bnll, nll, err = kt.losses(torch, bx, *kt.predictions(torch, bx, nz))
            figures = {**_figures(bnll, nll, err, train), **_noise_figures(nz, use_imu, slow)}
            held_figs = _figures(bnll, nll, err, test) if n_hold else {}
            # figures and held-out score of theta after `it` steps
            score = held_figs["nll"] if n_hold else -it
            if score < best[0]:
                best = (score, it, theta.detach().clone(), figures, held_figs)
            if it == iterations or (n_hold and it - best[1] >= patience):
                break
            history.append(figures)
            bnll[train].mean().backward()
            opt.step()
            if on_step is not None:
                on_step(it + 1, figures)
        with torch.no_grad():
            nz = kt.noise(torch, best[2], floors)
    finally:
        torch.set_num_threads(threads)
    Qc, R = nz.Qc.numpy().copy(), nz.R.numpy().copy()
    sigma_a = math.sqrt(float(nz.sa2)) if use_imu else None
    clamped: dict[str, float] = {}
    return {
        "params": kf_options(Qc, R, sigma_a, sigma_ref, unstated, clamped),
        "clamped": clamped,
        "Q_c": Qc.tolist(),
        "R": R.tolist(),
        "sigma_a": sigma_a,
        "slow": nz.slow2.numpy().tolist() if slow and bool(bx.truth_w.any()) else None,
        "sigma_ref_m": sigma_ref,
        "gps_profile": gps_profile,
        "loss": {"train": best[3], **({"holdout": best[4]} if n_hold else {})},
        "iterations": len(history),
        "best_iteration": best[1],
        "segments": {"train": int(B - n_hold), "holdout": int(n_hold)},
        "fixes": {"train": int(train.sum()), "holdout": int(test.sum())},
        "seconds": time.perf_counter() - t_start,
        "history": history,
    }


def _figures(bnll: Any, nll: Any, err: Any, sel: Any) -> dict[str, float]:
    """Mean beta-NLL, NLL [nats] and error [m] over the selected fixes (tensors)."""
    return {
        "beta_nll": float(bnll.detach()[sel].mean()),
        "nll": float(nll.detach()[sel].mean()),
        "error_m": float(err[sel].mean()),
    }


def _noise_figures(nz: Any, imu: bool, slow: bool) -> dict[str, float]:
    """q [m^2/s^5] (the mean eigenvalue of Q_c), fix sigma [m], (``imu``) sigma_a [m/s^2]
    and (``slow``) sigma_slow [m] (square roots of mean eigenvalues) of a Noise."""
    out = {
        "q": 0.5 * float(nz.Qc.detach().trace()),
        "sigma_fix_m": math.sqrt(0.5 * float(nz.R.detach().trace())),
    }
    if imu:
        out["sigma_a"] = math.sqrt(float(nz.sa2.detach()))
    if slow:
        out["sigma_slow_m"] = math.sqrt(0.5 * float(nz.slow2.detach().trace()))
    return out
