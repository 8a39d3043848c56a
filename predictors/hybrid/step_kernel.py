"""The ``hybrid``'s network step after its window, as one compiled call: the prior input,
the input box, the network's core and the correction's knots (numba, compiled at the
first call; :mod:`posbench.predictors._kernels`).

The arithmetic is the module doc's of :mod:`posbench.predictors.hybrid.predictor`, in the
order it is written there and without fast-math (float64 throughout, the prior input cast
to the network's float32 last), so the answers are those of the same steps written as
Python: only the calls between them are gone (about 8 us a step in Python and numpy
glue: a list per step, ``tolist``, four dispatches).

Statuses of :func:`network_step`: :data:`STEPPED` (knots written), :data:`OUTSIDE` (the
window is outside the training inputs' box: no correction), :data:`NOT_FINITE` (an output
is not finite or a log variance above :data:`MAX_LOGVAR`), :data:`NO_CORE` (the prior input
is written and inside the box, but the model has no core: the caller runs the full graph,
then :func:`output_knots` on its output).
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._kernels import kernel
from posbench.predictors.hybrid.gate import inside_envelope
from posbench.predictors.lstm.core_kernel import core_forward

#: a log variance above this [log m^2] counts as not finite (exp would overflow)
MAX_LOGVAR = 80.0
STEPPED, OUTSIDE, NOT_FINITE, NO_CORE = 0, 1, 2, 3


@kernel
def output_knots(
    out: np.ndarray, c: float, s: float, shrink: np.ndarray, knots: np.ndarray
) -> bool:
    """The network's output ``out`` (16,) float32 (per horizon dx, dy [m, heading frame],
    log var along, across [log m^2]) as the correction's knots ``knots`` (4, H + 1) float64:
    rows world dx, world dy [m, ENU] (times ``shrink`` (H + 1,)), log var along, across;
    column 0 (h = 0) zero. False, and ``knots`` untouched, where an output is not finite
    or a log variance is above :data:`MAX_LOGVAR`."""
    n_h = out.shape[0] // 4
    for i in range(out.shape[0]):
        if not math.isfinite(out[i]):
            return False
    for k in range(n_h):
        if out[4 * k + 2] > MAX_LOGVAR or out[4 * k + 3] > MAX_LOGVAR:
            return False
    for r in range(4):
        knots[r, 0] = 0.0
    for k in range(n_h):
        x = np.float64(out[4 * k])
        y = np.float64(out[4 * k + 1])
        a = shrink[k + 1]
        knots[0, k + 1] = a * (c * x - s * y)
        knots[1, k + 1] = a * (s * x + c * y)
        knots[2, k + 1] = np.float64(out[4 * k + 2])
        knots[3, k + 1] = np.float64(out[4 * k + 3])
    return True


@kernel
def network_step(
    pos: np.ndarray,
    gx: float,
    gy: float,
    c: float,
    s: float,
    features: np.ndarray,
    prior: np.ndarray,
    box: bool,
    fmin: np.ndarray,
    fmax: np.ndarray,
    pmin: np.ndarray,
    pmax: np.ndarray,
    core: bool,
    weights: np.ndarray,
    hidden: int,
    slope: float,
    out: np.ndarray,
    shrink: np.ndarray,
    knots: np.ndarray,
) -> int:
    """One network step after the window: the prior's positions ``pos`` (H, 2) [m, ENU] at
    the horizons, less the window's last grid point (gx, gy), rotated into the heading
    frame (cos, sin of the heading: c, s) into ``prior`` (H, 2) float32; the box check of
    ``features`` (8, F) float32 and ``prior`` where ``box``; then, where ``core``, the
    network's core (packed ``weights``, ``hidden`` units, LeakyReLU ``slope``) into ``out``
    (4 H,) float32 and :func:`output_knots`. Returns a status (module doc)."""
    for k in range(pos.shape[0]):
        dx = pos[k, 0] - gx
        dy = pos[k, 1] - gy
        prior[k, 0] = np.float32(c * dx + s * dy)
        prior[k, 1] = np.float32(c * dy - s * dx)
    if box and not inside_envelope(features, prior, fmin, fmax, pmin, pmax):
        return OUTSIDE
    if not core:
        return NO_CORE
    core_forward(features, prior.reshape(prior.size), weights, hidden, out.shape[0], slope, out)
    if not output_knots(out, c, s, shrink, knots):
        return NOT_FINITE
    return STEPPED
