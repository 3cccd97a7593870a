"""Test-wide settings. In CI (``CI`` set, as ``.ci/run`` runs) hypothesis draws its examples from a fixed
seed, so a red CI is reproducible and never a lottery; locally every run explores new examples."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture(scope="module")
def zenoh_router():
    """A Zenoh router in this process on a free loopback port, for one test module; yields its endpoint."""
    import zenoh

    from agent.net.zenoh_transport import router_config
    from mesh_sim.launcher import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = zenoh.open(router_config([endpoint]))
    try:
        yield endpoint
    finally:
        session.close()
