"""Drives through predictors, as a vehicle would see them: a drive prepared (fixes fed,
queries, references; :mod:`~posbench.replay.prepare`), replayed event by event
(:mod:`~posbench.replay.loop`) in worker processes or on Ray
(:mod:`~posbench.replay.runner`, :mod:`~posbench.replay.executors`), with the predictors
and their options set up first (:mod:`~posbench.replay.predictor_setup`)."""
