"""The figures of a ``bench run``, drawn from the traces alone: one function per figure
(:mod:`posbench.figures.distributions`, :mod:`posbench.figures.maps`,
:mod:`posbench.figures.per_drive`), one writer (:mod:`posbench.figures.writer`), one style
(:mod:`posbench.figures.style`). The paper's figures replay a drive, so they are
:mod:`posbench.predictor_tools.paper_figures`.

Every figure is drawn from the per-query traces (one row per query: ``t_query`` [s] in
drive time, positions ``x, y, x_ref, y_ref`` [m] in a local ENU frame, ``error_m`` [m];
see :data:`posbench.scoring.schema.TRACE_COLUMNS`). :func:`~posbench.figures.writer.write_plots`
writes them and never raises on thin data: a figure with nothing to show is not written, and
:class:`~posbench.figures.style.PlotsWritten` says why.

Figures (each written once per requested format, see :data:`~posbench.figures.style.FORMATS`):

- ``error_cdf``: future / now error CDFs, one line per predictor (log x);
- ``error_vs_speed``: mean future-point error per speed bin (empty bins dropped);
- ``error_vs_since_fix``: mean current-position error by time since the last fix
  (runs with GPS outages only; empty bins dropped);
- ``path``: 40 s of the most-turning drive, with zoomed panels around its worst moments;
- ``trajectory_error``: that drive's reference path coloured by each predictor's
  future-point error, one panel per predictor, one shared colour scale;
- ``outage_lengths`` (runs with the ``outage-lengths`` dropout profile): FDE [m] and FDE
  [% of the distance since the last fix] against outage length, with 95 % intervals, drawn
  from results.json (:func:`~posbench.figures.writer.write_result_plots`: the intervals are
  the aggregation's);
- ``drives/<drive>-error_over_time``: per drive, future-point error over drive time,
  with GPS outages, scenario labels and the warm-up shaded.

Warm-up: where the traces have a boolean ``warmup`` column (queries before a drive's
second fix), those rows are left out of every figure but the per-drive error over time,
which shades them. Old traces without the column are drawn whole.
"""
