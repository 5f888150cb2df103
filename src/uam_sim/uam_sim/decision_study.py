"""``python -m uam_sim.decision_study``: the decision study. The code is :mod:`uam_sim.studies.decision_study`."""

import sys

from .studies.decision_study import main

if __name__ == "__main__":
    sys.exit(main())
