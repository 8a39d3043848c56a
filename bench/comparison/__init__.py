"""Saved runs compared (``bench compare``, :func:`posbench.compare`): figures aligned per
predictor, data set, route type and drive, paired differences over shared drives, the
uncertainty figures side by side and the accuracy gate for CI. Reads saved runs only."""
