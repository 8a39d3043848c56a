"""``bench run`` and ``bench score`` as library functions: load the drives, check their data,
replay or score, aggregate, publish (:mod:`~posbench.pipeline.plan`, :mod:`~posbench.pipeline.run`,
:mod:`~posbench.pipeline.score`). The one place that composes every other part of the
harness; the command line and :func:`posbench.run` both call it."""
