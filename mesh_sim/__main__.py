"""``python -m mesh_sim``: the ``skymesh`` command line."""

import sys

from mesh_sim.cli import main

if __name__ == "__main__":
    sys.exit(main())
