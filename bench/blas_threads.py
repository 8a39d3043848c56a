"""One OpenBLAS thread unless the user says otherwise: import before numpy.

numpy's OpenBLAS starts a thread per core. The products ``bench`` does are small (the
bootstrap's 2000 x D resample matrices, a few hundred columns), and the worker processes
already hold the cores: with its threads, aggregating the shared data took 16-20 s on the
2-core development machine under load, on one thread 5.7 s, with the same results to the
bit (README, Performance). Imported first by :mod:`posbench.cli.app`; an ``OPENBLAS_NUM_THREADS``
already set is kept. Setting it after numpy has loaded has no effect.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
