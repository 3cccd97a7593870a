"""The router a run opens from a Zenoh JSON5 file (``skymesh run --zenoh-config FILE``), and where its children
connect to it.

The file is a standard Zenoh configuration (e.g. listening on every interface, so that a ground station on another
machine can attach with ``skymesh view``). It must name the endpoints it listens on as a list
(``listen: { endpoints: ["tcp/0.0.0.0:7447"] }``) and be a router (``mode: "router"``; a file without a mode is
made one). The run's own processes connect to its first endpoint, with an unspecified address
(``0.0.0.0``, ``[::]``) replaced by loopback: they run on this machine.
"""

from __future__ import annotations

import json

import zenoh

from agent.net.zenoh_transport import load_config, open_session

_LOOPBACK = {"0.0.0.0": "127.0.0.1", "[::]": "[::1]"}  # an unspecified listen address -> where a local child dials


def local_endpoint(listen: str) -> str:
    """``tcp/0.0.0.0:7447`` -> ``tcp/127.0.0.1:7447``: where a process on this machine reaches a listen endpoint."""
    protocol, sep, address = listen.partition("/")
    host, colon, port = address.rpartition(":")
    if not sep or not colon:
        raise ValueError(f"listen endpoint {listen!r} is not PROTOCOL/HOST:PORT, e.g. tcp/0.0.0.0:7447")
    return f"{protocol}/{_LOOPBACK.get(host, host)}:{port}"


def router_config_from_file(path: str) -> tuple[zenoh.Config, str]:
    """The router configuration in ``path`` and the endpoint the run's children connect to; ``ValueError`` naming
    the file when it cannot be read, is not a router, or lists no endpoints to listen on."""
    config = load_config(None, path)  # a ValueError naming the file when it is not Zenoh JSON5
    mode = json.loads(config.get_json("mode"))
    if mode is None:
        config.insert_json5("mode", json.dumps("router"))
    elif mode != "router":
        raise ValueError(f"{path}: mode is {mode!r}: skymesh run opens a router (mode: \"router\")")
    endpoints = json.loads(config.get_json("listen/endpoints"))
    if not isinstance(endpoints, list) or not endpoints or not all(isinstance(e, str) for e in endpoints):
        raise ValueError(f"{path}: listen/endpoints must list where the run's router listens, "
                         f"e.g. [\"tcp/0.0.0.0:7447\"]; got {json.dumps(endpoints)}")
    try:
        return config, local_endpoint(endpoints[0])
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def router_from_file(path: str) -> tuple[zenoh.Session, str]:
    """The run's router opened from ``path`` (a :class:`~agent.net.zenoh_transport.SessionError` when, e.g., its
    port is taken), and the endpoint its children connect to."""
    config, endpoint = router_config_from_file(path)
    return open_session(config), endpoint
