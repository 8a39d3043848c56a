"""The Kalman filters as member objects: the readable reference the compiled rows of
``posbench.predictors.kalman`` are held to in the tests, and no longer part of the package.

:class:`~reference_filters.linear_kalman.LinearKalman` (one CA filter on
:class:`~reference_filters.ca_filter.CaFilter2D`), :class:`~reference_filters.ctra_ekf.CtraEkf`
(one CTRA EKF) and :class:`~reference_filters.model_bank.ModelBank` (members selected by the
likelihood of their fix predictions) run one Python object per filter; they share the
package's motion models (``posbench.metrics.ca_model``,
``posbench.predictors.kalman.ctra_model``), inputs and helpers.
:func:`~reference_filters.banks.member_bank` builds a bank of them with a row bank's options.
filterpy checks the member objects in turn (tests/predictors/test_filter_fastpath.py).
"""
