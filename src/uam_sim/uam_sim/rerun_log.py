"""``python -m uam_sim.rerun_log``: a recording as a Rerun .rrd. The code is :mod:`uam_sim.views.rerun_log`."""

import sys

from .views.rerun_log import main

if __name__ == "__main__":
    sys.exit(main())
