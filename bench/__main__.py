"""``python -m posbench ...`` runs the ``bench`` command line."""

import sys

try:
    from posbench.cli import main
except KeyboardInterrupt:  # Ctrl-C before main's own handler is in place
    sys.stderr.write("error: interrupted\n")
    sys.exit(130)

main()
