"""``python -m uam_sim.capacity_study``: the capacity study. The code is :mod:`uam_sim.studies.capacity_study`."""

import sys

from .studies.capacity_study import main

if __name__ == "__main__":
    sys.exit(main())
