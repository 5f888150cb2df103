"""``python -m uam_sim.capacity_report``: the capacity study's report from its tables. The code is :mod:`uam_sim.reports.capacity_report`."""

import sys

from .reports.capacity_report import main

if __name__ == "__main__":
    sys.exit(main())
