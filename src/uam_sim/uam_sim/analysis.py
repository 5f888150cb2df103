"""``python -m uam_sim.analysis``: summary and verdict of a recording. The code is :mod:`uam_sim.audit.analysis`."""

import sys

from .audit.analysis import main

if __name__ == "__main__":
    sys.exit(main())
