"""``python -m uam_sim.large_instances``: where optimisation pays on large instances. The code is :mod:`uam_sim.studies.large_instances`."""

import sys

from .studies.large_instances import main

if __name__ == "__main__":
    sys.exit(main())
