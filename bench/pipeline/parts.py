"""Where a run keeps what its processes hand each other on disk while it runs: the drives as
their loading processes wrote them (``drives/``, :mod:`posbench.scenarios.stored_drive`) and
the drives' traces as the workers wrote them, a folder of Parquet parts
(:func:`posbench.scoring.part_writer.write_part`) per seed (``seed-N/``).

With an output folder it lies inside it (``OUT/.parts-XXXX``), so that on a cluster the
workers write where the driver reads (``--out`` on a shared file system); without one, in
the system's temporary folder. It is removed when the run is published (the traces are then
in ``traces.parquet``), when the run fails, or - for a run kept only in memory, whose
:class:`~posbench.saved_run.run.Run` reads its traces from the parts - when that object is
gone.
"""

from __future__ import annotations

import shutil
import tempfile
import weakref
from pathlib import Path
from types import TracebackType


class PartsFolder:
    """The parts folder of one run (a context manager: removed on exit unless kept)."""

    def __init__(self, out: Path | None) -> None:
        #: the output folders this made (to leave none behind when the run stops before
        #: writing anything there)
        self._made: list[Path] = []
        if out is not None:
            for folder in (*reversed(out.parents), out):
                if not folder.exists():
                    folder.mkdir()
                    self._made.append(folder)
        # absolute: Ray workers need not share this process's working folder
        self.path = Path(
            tempfile.mkdtemp(prefix=".parts-" if out else "posbench-parts-", dir=out)
        ).resolve()
        self._kept = False

    def seed(self, index: int) -> Path:
        """The folder of the ``index``-th seed's parts (0: the run's own)."""
        return self.path / f"seed-{index}"

    @property
    def drives(self) -> Path:
        """The folder of the run's drives, as their loading processes wrote them
        (:func:`posbench.scenarios.stored_drive.store_drive`)."""
        return self.path / "drives"

    def drop_drives(self) -> None:
        """Remove the drives (once every replay and figure that reads them is done)."""
        shutil.rmtree(self.drives, ignore_errors=True)

    def drop(self, index: int) -> None:
        """Remove the ``index``-th seed's parts (once its figures are taken)."""
        shutil.rmtree(self.seed(index), ignore_errors=True)

    def keep_for(self, run: object) -> None:
        """Keep the parts while ``run`` reads from them (a run without an output folder),
        removing them when it is garbage-collected or the interpreter exits."""
        if getattr(run, "_trace_parts", ()):
            self._kept = True
            weakref.finalize(run, shutil.rmtree, str(self.path), True)

    def __enter__(self) -> PartsFolder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if not self._kept or exc_type is not None:
            shutil.rmtree(self.path, ignore_errors=True)
        for folder in reversed(self._made):  # those still empty: nothing was written there
            try:
                folder.rmdir()
            except OSError:
                break
