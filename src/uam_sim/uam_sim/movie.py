"""``python -m uam_sim.movie``: a movie of a recording. The code is :mod:`uam_sim.views.movie`."""

import sys

from .views.movie import main

if __name__ == "__main__":
    sys.exit(main())
