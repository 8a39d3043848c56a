"""The kf's noise parameters tuned by gradient: the filter over a batch of drives as
arrays (:mod:`~posbench.predictors.kalman.tuning.steps`), run differentiably in torch
(:mod:`~posbench.predictors.kalman.tuning.torch_steps`, the ``train`` extra), driven by
:func:`~posbench.predictors.kalman.tuning.gradient.gradient_tune` (``bench tune kf
--method gradient``)."""
