"""Where ``bench run`` does its work: local processes or a Ray cluster.

``local`` is :func:`posbench.replay.runner.run` (one process per drive). ``ray`` fans the
work out as one Ray task per (drive, predictor) pair: each task prepares the drive
(deterministic: seeds derive from the master seed and the drive's name) and replays
one predictor, and the parts are merged per drive in the configured predictor order,
so the traces - and every error figure of ``results.json`` - are identical to the
local executor's. Only the measured latencies differ.

A task that raises, or whose worker dies, is retried ``max_retries`` times; if it
still fails, its drive is reported as skipped (``worker failed: ...``) with the
predictor and the error named, never silently dropped. Ray is imported lazily and is
an extra: ``pip install 'posbench-harness[ray]'``.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pandas as pd

from posbench.config import RunConfig
from posbench.predictors.catalogue import BUILT_IN, Entry, register
from posbench.predictors.registry import available, base_name, predictor_class, resolve
from posbench.replay.runner import part_name, run, run_drive
from posbench.scenarios.drive import Drive
from posbench.scenarios.stored_drive import DriveInfo, StoredDrive
from posbench.scoring.records import DriveRun, merge_predictor_runs

EXECUTORS = ("local", "ray")
RAY_MISSING = "--executor ray needs Ray: pip install 'posbench-harness[ray]'"
DEFAULT_RETRIES = 2


class ExecutorError(Exception):
    """The executor could not start (Ray missing, cluster unreachable): one line for the user."""


def ray_available() -> bool:
    """Whether Ray is installed (without importing it: that takes ~1 s)."""
    try:
        return importlib.util.find_spec("ray") is not None
    except (ImportError, ValueError):  # a broken install, or sys.modules["ray"] = None
        return False


def run_local(
    drives: Sequence[Drive | StoredDrive],
    cfg: RunConfig,
    workers: int = 2,
    on_done: Callable[[DriveRun], None] | None = None,
    limit: bool = False,
    parts: Path | None = None,
) -> list[DriveRun]:
    """The local executor: :func:`posbench.replay.runner.run` in ``workers`` processes
    (``limit``: each drive's bound too; ``parts``: where the tasks write their traces)."""
    return run(drives, cfg, workers=workers, on_done=on_done, limit=limit, parts=parts)


def run_predictor(
    drive: Drive | StoredDrive,
    cfg: RunConfig,
    name: str | None,
    entries: dict[str, Entry],
    limit: bool = False,
    parts: Path | None = None,
    part: str = "drive",
) -> DriveRun:
    """One task: ``drive`` replayed through predictor ``name`` only (all of ``cfg``'s when
    None). ``entries`` re-registers the driver's predictors, so predictors registered at
    run time are known in a fresh worker (their module must be importable there).
    ``limit``: the drive's bound too, by the task of the first predictor only. ``parts``:
    the folder the task writes its traces to, as part ``part`` (on a cluster, one every
    node reaches); the record returned names the file instead of holding them."""
    for n, e in entries.items():
        register(n, e.target, e.description, **e.defaults)
    return run_drive(
        drive,
        cfg if name is None else replace(cfg, predictors=(name,)),
        limit=limit and (name is None or name == cfg.predictors[0]),  # once per drive
        parts=parts,
        part=part,
    )


@dataclass(frozen=True)
class _Failed:
    predictor: str | None
    error: str


def failed_run(
    drive: Drive | StoredDrive, predictor: str | None, error: str, attempts: int
) -> DriveRun:
    """The record of a drive whose task failed after all retries: skipped, with the reason."""
    drive_info = DriveInfo.of(drive)
    what = f"predictor {predictor}: " if predictor else ""
    return DriveRun(
        drive_info.name,
        drive_info.meta.format,
        "",
        [],
        list(drive_info.meta.warnings),
        pd.DataFrame(),
        skipped=f"worker failed: {what}{error} (after {attempts} attempts)",
        duration_s=drive_info.duration_s,
    )


def _error_line(exc: BaseException) -> str:
    cause = getattr(exc, "cause", None) or exc  # RayTaskError wraps the task's exception
    text = str(cause).strip().splitlines()
    return f"{type(cause).__name__}: {text[0][:200] if text else ''}".rstrip(": ")


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise ExecutorError(RAY_MISSING) from None
    return ray


def run_ray(
    drives: Sequence[Drive | StoredDrive],
    cfg: RunConfig,
    address: str | None = None,
    num_cpus: int = 2,
    max_retries: int = DEFAULT_RETRIES,
    on_done: Callable[[DriveRun], None] | None = None,
    limit: bool = False,
    parts: Path | None = None,
) -> list[DriveRun]:
    """Run every (drive, predictor) pair as a Ray task; the result is in drive order
    (``limit``: each drive's bound too, :func:`run_predictor`; ``parts``: the folder the
    tasks write their traces to, so only small records return to the driver).

    Without ``address`` a local Ray instance with ``num_cpus`` CPUs is started and shut
    down afterwards; with one (``ray://host:10001`` or ``host:6379`` or ``auto``) the
    run connects to that cluster, whose nodes must have posbench installed. If Ray is
    already initialised in this process, that session is used and left running.
    ``on_done`` is called as each drive completes."""
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no usage reports leave the machine
    ray = _import_ray()
    started = not ray.is_initialized()
    if started:
        try:
            if address:
                ray.init(address=address, log_to_driver=False)
            else:
                # a local instance talks over loopback only, never the machine's interfaces
                ray.init(
                    num_cpus=num_cpus,
                    include_dashboard=False,
                    log_to_driver=False,
                    ignore_reinit_error=True,
                    _node_ip_address="127.0.0.1",
                )
        except (ConnectionError, RuntimeError, ValueError) as e:
            raise ExecutorError(
                f"cannot start Ray{' at ' + address if address else ''}: {_error_line(e)}"
            ) from None
    try:
        return _fan_out(ray, drives, cfg, max_retries, on_done, limit, parts)
    finally:
        if started:
            ray.shutdown()


def import_roots(names: Sequence[str]) -> list[str]:
    """The ``sys.path`` folders the driver imported the non-built-in predictors of ``names``
    from (``module:Class`` import paths, entry points, run-time registrations), in order;
    site-packages folders are left out (an installed plugin is installed on the workers too)."""
    import site

    installed = {os.path.realpath(p) for p in [*site.getsitepackages(), site.getusersitepackages()]}
    roots: list[str] = []
    for name in names:
        if resolve(name).source == BUILT_IN:
            continue
        module = sys.modules.get(predictor_class(name).__module__)
        path = getattr(module, "__file__", None)
        if not path:
            continue
        path = os.path.realpath(path)
        here = [os.path.realpath(p or os.curdir) for p in sys.path]
        inside = [p for p in here if path.startswith(p.rstrip(os.sep) + os.sep)]
        root = max(inside, key=len, default=None)
        if root and root not in roots and root not in installed:
            roots.append(root)
    return roots


def worker_runtime_env(names: Sequence[str]) -> dict[str, Any] | None:
    """The Ray ``runtime_env`` that lets workers import the predictors of ``names`` that are
    not part of posbench, or None when every one is built in.

    Workers import a predictor by its name (``mymod:MyPredictor``, or an entry point's
    ``module:Class``), so its folder must be on their ``sys.path``. A local Ray instance that
    ``bench`` starts inherits the driver's environment (PYTHONPATH), and Ray itself adds the
    driver's current folder; but a cluster started elsewhere (``--address``), or a session
    already running in this process, knows neither a PYTHONPATH nor a ``sys.path`` entry the
    driver added (``import_from_cwd``, a test's ``sys.path``). So each task gets the folders
    the driver imported them from in front of the worker's own PYTHONPATH (Ray expands
    ``${PYTHONPATH}`` to the worker's value). Checked: a module importable only through the
    driver's ``sys.path`` fails in the workers without this and runs with it
    (tests/predictors/test_plugins.py). On a cluster, those folders must exist on every node (a
    shared file system), or the plugin be installed there as a package (an entry point)."""
    roots = import_roots(names)
    if not roots:
        return None
    return {"env_vars": {"PYTHONPATH": os.pathsep.join([*roots, "${PYTHONPATH}"])}}


def _fan_out(
    ray: Any,
    drives: Sequence[Drive | StoredDrive],
    cfg: RunConfig,
    max_retries: int,
    on_done: Callable[[DriveRun], None] | None,
    limit: bool = False,
    parts: Path | None = None,
) -> list[DriveRun]:
    task = ray.remote(num_cpus=1, max_retries=max_retries, retry_exceptions=True)(run_predictor)
    env = worker_runtime_env(cfg.predictors)
    if env:
        task = task.options(runtime_env=env)
    names: tuple[str | None, ...] = cfg.predictors or (None,)
    known = available()
    entries = {base_name(n): known[base_name(n)] for n in cfg.predictors if base_name(n) in known}
    cfg_ref = ray.put(cfg)
    pending: dict[Any, tuple[int, int]] = {}
    for i, d in enumerate(drives):
        drive_ref = ray.put(d)  # once per drive (a stored one: its file), shared by its tasks
        for j, name in enumerate(names):
            part = part_name(i, None if name is None else j)
            pending[task.remote(drive_ref, cfg_ref, name, entries, limit, parts, part)] = (i, j)
    pieces: list[list[DriveRun | _Failed | None]] = [[None] * len(names) for _ in drives]
    left = [len(names)] * len(drives)
    out: list[DriveRun | None] = [None] * len(drives)
    refs = list(pending)
    while refs:
        done, refs = ray.wait(refs, num_returns=1)
        for ref in done:
            i, j = pending.pop(ref)
            try:
                pieces[i][j] = ray.get(ref)
            except ray.exceptions.RayError as e:
                pieces[i][j] = _Failed(names[j], _error_line(e))
            left[i] -= 1
            if left[i] == 0:
                failed = [p for p in pieces[i] if isinstance(p, _Failed)]
                out[i] = drive_run = (
                    failed_run(drives[i], failed[0].predictor, failed[0].error, max_retries + 1)
                    if failed
                    else merge_predictor_runs([p for p in pieces[i] if isinstance(p, DriveRun)])
                )
                pieces[i] = []  # free the records once merged
                if on_done:
                    on_done(drive_run)
    return [r for r in out if r is not None]


def run_drives(
    drives: Sequence[Drive | StoredDrive],
    cfg: RunConfig,
    executor: str = "local",
    workers: int = 2,
    address: str | None = None,
    on_done: Callable[[DriveRun], None] | None = None,
    limit: bool = False,
    parts: Path | None = None,
) -> list[DriveRun]:
    """Run ``drives`` on ``executor`` (``local`` or ``ray``); results in drive order
    (``limit``: each drive's bound too, :func:`posbench.replay.runner.run_drive`;
    ``parts``: the folder every task writes its traces to, so that only small records
    come back; None: the records hold them)."""
    if executor == "local":
        if address:
            raise ExecutorError("--address is for --executor ray")
        return run_local(drives, cfg, workers=workers, on_done=on_done, limit=limit, parts=parts)
    if executor == "ray":
        return run_ray(
            drives,
            cfg,
            address=address,
            num_cpus=max(1, workers),
            on_done=on_done,
            limit=limit,
            parts=parts,
        )
    raise ExecutorError(f"--executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
