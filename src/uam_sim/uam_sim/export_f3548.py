"""``python -m uam_sim.export_f3548``: a recording's F3548 operational intents as JSON. The code is :mod:`uam_sim.f3548.export_f3548`."""

import sys

from .f3548.export_f3548 import main

if __name__ == "__main__":
    sys.exit(main())
