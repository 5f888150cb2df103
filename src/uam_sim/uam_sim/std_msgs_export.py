"""``python -m uam_sim.std_msgs_export``: a recording with the standard-message view topics added. The code is :mod:`uam_sim.views.std_msgs_export`."""

import sys

from .views.std_msgs_export import main

if __name__ == "__main__":
    sys.exit(main())
