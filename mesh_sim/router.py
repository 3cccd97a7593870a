"""``skymesh router --config FILE``: the Zenoh router of a deployment across machines (DESIGN.md §5).

On one machine ``skymesh run`` opens its own router on loopback. Across machines the agents, the ground
station and (in hardware-in-the-loop runs) the simulated world connect to a router that is started from a
standard Zenoh JSON5 file, typically ``deploy/router.json5``: TLS with mutual authentication, so that a
process without a certificate signed by the fleet's CA cannot open a session at all, and access control,
so that an agent may only publish under its own name. The file is the kind Eclipse's ``zenohd`` reads; this
command needs nothing beyond the ``eclipse-zenoh`` wheel the agents already use, and opens it in router
mode whatever its ``mode`` says.

The process prints the endpoints it listens on (as configured) and whether mTLS and access control are on,
then runs until SIGINT or SIGTERM (exit 0) or, with ``--parent-pid``, until that process is gone (exit 0: a
launcher that was SIGKILLed — ``skymesh testbed`` starts one router per host — leaves no router behind). A
config file that is missing, unreadable or refused by Zenoh (a syntax error, an unknown field, a certificate
that cannot be read, a port in use) is one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import threading

import zenoh

from agent.net.zenoh_transport import SessionError, load_config, open_session
from agent.runtime import install_stop_handlers, parent_alive, usage_error


def open_router(config_file: str) -> tuple[zenoh.Session, str]:
    """A router session from ``config_file`` and its :func:`describe` line. ``ValueError`` if Zenoh refuses the
    file, :class:`SessionError` if it cannot open the session (a certificate it cannot read, a port in use)."""
    config = load_config(None, config_file)
    config.insert_json5("mode", json.dumps("router"))
    summary = describe(config)
    return open_session(config), summary


def describe(config: zenoh.Config) -> str:
    """What a user needs to see at start: where the router listens and which protections are on."""
    listen = json.loads(config.get_json("listen/endpoints"))
    mtls = json.loads(config.get_json("transport/link/tls/enable_mtls"))
    acl = json.loads(config.get_json("access_control/enabled"))
    return (f"listening on {', '.join(map(str, listen)) or 'no endpoint'}; mutual TLS {'on' if mtls else 'OFF'}; "
            f"access control {'on' if acl else 'OFF'}")


def run(config_file: str, stop: threading.Event, parent_pid: int | None = None) -> int:
    """Serve until ``stop`` is set or the process ``parent_pid`` (given: this one's parent) is gone; the exit
    code."""
    try:
        session, summary = open_router(config_file)
    except (ValueError, SessionError) as err:
        return usage_error("skymesh router", err)
    try:
        print(f"skymesh router {session.info.zid()}: {summary}", flush=True)
        while not stop.wait(0.5):  # a bounded wait: the signal handler runs between waits
            if parent_pid is not None and not parent_alive(parent_pid):
                print(f"skymesh router: parent process {parent_pid} is gone; stopping", flush=True)
                break
    finally:
        session.close()
    return 0


def run_from_args(args: argparse.Namespace) -> int:
    """``skymesh router``: serve until SIGINT or SIGTERM."""
    zenoh.init_log_from_env_or("error")
    stop = threading.Event()
    install_stop_handlers(stop)
    return run(args.config, stop, args.parent_pid)
