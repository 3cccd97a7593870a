"""``python -m mesh_sim.autopilot``: one PX4-like autopilot simulator (see :mod:`mesh_sim.autopilot`)."""

import sys

from mesh_sim.autopilot.cli import main

if __name__ == "__main__":
    sys.exit(main())
