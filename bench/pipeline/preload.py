"""Import what the next step of ``bench run`` needs while worker processes do this one.

Two lists: :data:`REPLAY_MODULES`, imported while the loader processes read the recordings,
are those every replay worker would otherwise import for itself (scipy.interpolate for the
references: ~0.7 s each), inherited by the workers forked after loading. :data:`MODULES`:
after the replay, the main process aggregates while forked children draw the figures;
importing matplotlib (and its Agg backend, in every child), scipy.special and the report
modules there costs ~0.65 s on the critical path. During the replay the main process only
waits for its workers, so :class:`Preload` imports them then, in a thread, once the
worker processes exist (forking while another thread imports could leave a module lock
held in the child). Joined before the figure children are forked, which then inherit the
modules. Nothing changes but when the imports happen: a module that fails to import here
fails again, with its real error, where it is used.
"""

from __future__ import annotations

import importlib
import threading

#: imported by every replay worker (the reference cubic, the scenario labels)
REPLAY_MODULES = ("scipy.interpolate", "posbench.scenarios.labels")
#: imported after the replay by the main process or by every figure child
MODULES = (
    "matplotlib.figure",
    "matplotlib.backends.backend_agg",
    "scipy.special",
    "posbench.pipeline.results",
    "posbench.aggregation.aggregate",
    "posbench.aggregation.uncertainty",
    "posbench.aggregation.track",
    "posbench.figures.writer",
    "posbench.predictor_tools.paper_figures",
    "posbench.report.markdown",
    "posbench.saved_run.run",
    "posbench.tables.run_tables",
    "posbench.tables.stat_tables",
)


def _import_all(modules: tuple[str, ...]) -> None:
    for name in modules:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - raised again, properly, where it is used
            pass


class Preload:
    """Imports ``modules`` in a background thread from :meth:`start` on; :meth:`join`
    waits for them (call it before forking). Starting twice starts once."""

    def __init__(self, modules: tuple[str, ...] = MODULES) -> None:
        self._modules = modules
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(
                target=_import_all, args=(self._modules,), name="bench-preload", daemon=True
            )
            self._thread.start()

    def join(self) -> None:
        if self._thread is not None:
            self._thread.join()
