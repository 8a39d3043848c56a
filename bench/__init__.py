"""posbench: benchmark real-time vehicle position predictors on your drives."""

#: the distribution that installs the ``posbench`` package (``pip install posbench-harness``;
#: the name ``posbench`` on PyPI belongs to an unrelated project)
DISTRIBUTION = "posbench-harness"
