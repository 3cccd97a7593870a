"""The ``--web`` options of ``skymesh view`` and the observer, and what they ask for (:class:`Web`).

Apart from :mod:`mesh_sim.observer_web`, which serves, so that the command line can offer them without
importing Rerun (the ``observer*`` modules alone import it).
"""

from __future__ import annotations

import argparse
from typing import NamedTuple

WEB_PORT = 9090  # rerun's own default for the web viewer
GRPC_PORT = 9876  # rerun's own default for its gRPC server


class Web(NamedTuple):
    """Where to serve: the web viewer's HTTP port, its data's gRPC port, and the host name or address browsers
    reach this machine at (None: this machine's address on its network)."""

    port: int = WEB_PORT
    grpc_port: int = GRPC_PORT
    host: str | None = None


def port(text: str) -> int:
    """A TCP port to listen on, 1..65535 (0 would let the OS choose one the printed URL could not name)."""
    value = int(text) if text.isdigit() else -1
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be a TCP port, 1..65535; got {text!r}")
    return value


def add_web_arguments(p: argparse.ArgumentParser) -> None:
    """``--web [PORT]``, ``--grpc-port`` and ``--web-host``."""
    p.add_argument("--web", type=port, nargs="?", const=WEB_PORT, metavar="PORT",
                   help=f"serve Rerun's web viewer on this HTTP port (default {WEB_PORT}) and print its URL")
    p.add_argument("--grpc-port", type=port, default=GRPC_PORT, metavar="PORT",
                   help=f"with --web: the port the page reads the data from (default {GRPC_PORT})")
    p.add_argument("--web-host", metavar="HOST",
                   help="with --web: the name or address browsers reach this machine at (default: its address on "
                        "its network)")


def web_of(args: argparse.Namespace) -> Web | None:
    """The :class:`Web` the ``--web`` arguments ask for, or None without ``--web``."""
    return None if args.web is None else Web(args.web, args.grpc_port, args.web_host)
