"""The autopilot simulator's entry point, shared by ``skymesh autopilot`` and ``python -m mesh_sim.autopilot``."""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from collections.abc import Sequence

from agent.runtime import install_stop_handlers
from mesh_sim.autopilot.options import add_arguments, options_from_args
from mesh_sim.autopilot.simulator import run


def run_from_args(args: argparse.Namespace) -> int:
    """Run until SIGTERM / SIGINT (a clean stop, counters printed), the duration, or the parent's death."""
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(name)s: %(message)s")
    stop = threading.Event()
    install_stop_handlers(stop)
    return run(options_from_args(args), stop)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m mesh_sim.autopilot",
                                     description="A MAVLink autopilot simulator that behaves like PX4 SITL "
                                                 "(a subset) around skymesh's kinematic vehicle models.")
    add_arguments(parser)
    return run_from_args(parser.parse_args(argv))
