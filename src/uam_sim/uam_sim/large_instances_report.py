"""``python -m uam_sim.large_instances_report``: the large-instance study's report from its tables. The code is :mod:`uam_sim.reports.large_instances_report`."""

import sys

from .reports.large_instances_report import main

if __name__ == "__main__":
    sys.exit(main())
