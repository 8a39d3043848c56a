"""Traces -> the figures of results.json: summaries per predictor, data set, route type,
speed, outage and drive (:mod:`~posbench.aggregation.aggregate`), their confidence
intervals and the paired comparison (:mod:`~posbench.aggregation.intervals`), the spread
over seeds, along/cross-track errors and uncertainty. Pure given the traces: no replay, no
predictor, no file."""
