"""``python -m uam_sim.uss_server``: the F3548 USS-USS server. The code is :mod:`uam_sim.f3548.uss_server`."""

import sys

from .f3548.uss_server import main

if __name__ == "__main__":
    sys.exit(main())
