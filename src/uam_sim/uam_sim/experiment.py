"""``python -m uam_sim.experiment``: the paper's study (the in-process runner over a sweep). The code is :mod:`uam_sim.studies.experiment`."""

import sys

from .studies.experiment import main

if __name__ == "__main__":
    sys.exit(main())
