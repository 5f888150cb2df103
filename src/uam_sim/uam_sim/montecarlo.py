"""``python -m uam_sim.montecarlo``: the Monte-Carlo of disturbances. The code is :mod:`uam_sim.studies.montecarlo`."""

import sys

from .studies.montecarlo import main

if __name__ == "__main__":
    sys.exit(main())
