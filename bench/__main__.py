"""``python -m posbench ...`` runs the ``bench`` command line."""

from posbench.cli import main

main()
