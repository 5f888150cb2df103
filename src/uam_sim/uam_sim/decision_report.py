"""``python -m uam_sim.decision_report``: the decision study's report from its tables. The code is :mod:`uam_sim.reports.decision_report`."""

import sys

from .reports.decision_report import main

if __name__ == "__main__":
    sys.exit(main())
