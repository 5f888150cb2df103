"""``python -m uam_sim.report``: the paper study's report from its tables. The code is :mod:`uam_sim.reports.report`."""

import sys

from .reports.report import main

if __name__ == "__main__":
    sys.exit(main())
