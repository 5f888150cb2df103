"""``python -m uam_sim.preflight``: a run's node parameters and input files checked before any node starts. The code is :mod:`uam_sim.runner.preflight`."""

import sys

from .runner.preflight import main

if __name__ == "__main__":
    sys.exit(main())
