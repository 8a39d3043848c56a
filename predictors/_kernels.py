"""Compiled kernels (numba), compiled when one first runs: numba is imported then.

Why not ``numba.njit`` at import: numba and LLVM take ~70 MB of memory and ~0.5 s to
import, and the compiled kernels ~40 MB more once loaded. A process that builds
predictors without stepping a filter bank (``bench run``'s planning, which checks every
option by building each predictor once, ``bench predictors``, a report) should not pay
that: with the kernels compiled at import, the main process of a run over the shared data
grew from 731 MB to 792 MB at its peak.

Use: decorate a module's kernels with :func:`kernel` (or :func:`fast_kernel`, for float
arithmetic that may be reassociated: vectorised sums). The first call of any of them
replaces every kernel of that module by ``numba.njit(cache=True)`` of it (in the
module's namespace, where the kernels find one another and the callers find them, as
``module.name``), then makes the call. Compiled code is cached beside the module
(numba's ``cache=True``; numba falls back to a user cache folder where that is not
writable), so a new process loads it instead of compiling again. numba keys that cache on
the kernel's own file and bytecode, not on its options: after changing an option here,
delete the kernels' ``__pycache__/*.nbi`` and ``*.nbc`` files (or touch their modules), or
the old compiled code keeps running.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TypeVar, cast

F = TypeVar("F", bound=Callable[..., Any])

#: the attribute that marks a kernel's wrapper and holds the Python function
SOURCE = "_kernel_source"
#: the attribute that holds a kernel's options for ``numba.njit``
OPTIONS = "_kernel_options"
#: numba's fast-math flags without ``nnan`` and ``ninf``: sums may be reassociated and
#: vectorised, products contracted to FMAs, but NaN and infinity still propagate
REASSOCIATE = frozenset({"reassoc", "contract", "nsz", "arcp", "afn"})


def fast_kernel(fn: F) -> F:
    """:func:`kernel` compiled with :data:`REASSOCIATE` (results differ from the written
    order by float rounding) and numpy's error model: a float division by zero gives
    inf or NaN instead of raising ZeroDivisionError, so that a loop with a division has
    no branch and is vectorised (tanh over 2,048 gate values: 7.2 -> 1.1 us)."""
    return kernel(fn, fastmath=set(REASSOCIATE), error_model="numpy")


def kernel(fn: F, **options: Any) -> F:
    """Mark ``fn`` as a kernel of its module (module docstring); ``options`` go to
    ``numba.njit``. ``name = kernel(plain_function)`` of another module's plain function
    (scalar maths, e.g. :mod:`posbench.metrics.ca_model`'s) makes it a kernel of the
    module that writes this line, which its kernels call as ``name``."""
    namespace = fn.__globals__
    name = fn.__name__

    def first_call(*args: Any) -> Any:
        compile_module(namespace)
        return namespace[name](*args)

    setattr(first_call, SOURCE, fn)
    setattr(first_call, OPTIONS, options)
    first_call.__name__ = name
    first_call.__doc__ = fn.__doc__
    first_call.__wrapped__ = fn  # type: ignore[attr-defined]
    return cast(F, first_call)


def compile_module(namespace: dict[str, Any]) -> None:
    """Replace every kernel in a module's namespace by its numba dispatcher (lazy: each
    compiles, or loads from the cache, at its first call)."""
    from numba import njit

    for key, value in list(namespace.items()):
        source = getattr(value, SOURCE, None)
        if source is None:
            continue
        home = source.__globals__
        if home is namespace or home.get(source.__name__) is source:
            # this module's kernel, or another module's plain function compiled here
            namespace[key] = njit(cache=True, **getattr(value, OPTIONS, {}))(source)
        else:  # a kernel of another module, imported by name: its module's dispatcher
            if getattr(home[source.__name__], SOURCE, None) is not None:
                compile_module(home)
            namespace[key] = home[source.__name__]


#: the predictor classes whose kernels this process has run (:func:`warm_up_once`)
_WARM: set[type] = set()


def warm_up_once(make_probe: Callable[[], Any]) -> None:
    """Run every kernel a filter uses once, so that a run's timed steps never pay numba's
    loading (a few ms for the first fix steps of a process: kernels load from the cache at
    their first call): a new predictor from ``make_probe()`` is fed 8 s of made-up fixes
    (some stating an accuracy), IMU samples with and without a yaw, wheel speeds and
    queries up to 3.5 s after a fix. Once per predictor class and process."""
    probe = make_probe()
    cls = type(probe)
    if cls in _WARM:
        return
    probe.reset()
    for k in range(40):
        t = 0.2 * k
        for j in range(10):
            ti = t + 0.02 * j
            probe.observe_imu(ti, 0.1, 0.0, math.nan if j % 2 else 0.0, 0.01)
            probe.observe_speed(ti, 10.0 if k % 10 else 0.0)
        tf = t + 0.2
        probe.observe_gps(tf, 10.0 * tf, 0.01 * k, 0.5 if k % 2 else None)
        for dt in (0.2, 1.5, 3.5):
            probe.position_at(tf + dt)
            probe.covariance_at(tf + dt)
    _WARM.add(cls)


@kernel
def huber_log_likelihood(ex: float, ey: float, a: float, b: float, d: float, k: float) -> float:
    """``ModelBank._log_likelihood`` of a fix's innovation
    ``(ex, ey)`` [m] with covariance ``[[a, b], [b, d]]`` [m^2], Huber k ``k``; NaN where the
    covariance is not positive definite."""
    det = a * d - b * b
    if not det > 0.0:
        return math.nan
    nis = (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / det
    rho = nis if nis <= k * k else 2.0 * k * math.sqrt(nis) - k * k
    return -0.5 * (rho + math.log(det))


@kernel
def update_scores(S: Any, n: int, ll: int, scores: Any, keep: float) -> int:
    """The bank's scores after a fix (``ModelBank``): where
    every member row 0..n-1 has a likelihood in column ``ll`` of ``S``, ``keep`` x score +
    likelihood, and the best row (the first of the highest); else -1, the scores as they
    stand."""
    for i in range(n):
        if not S[i, ll] == S[i, ll]:
            return -1
    best = 0
    for i in range(n):
        scores[i] = keep * scores[i] + S[i, ll]
        if scores[i] > scores[best]:
            best = i
    return best
