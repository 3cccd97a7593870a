"""One sample through real Zenoh sessions, for tests of what a router does to what it forwards."""

from __future__ import annotations

import time

import zenoh


def first_sample(listener: zenoh.Session, talker: zenoh.Session, key: str, timeout: float = 10.0) -> zenoh.Sample:
    """The first sample ``listener`` hears on ``key`` while ``talker`` puts ``b"x"`` there every 50 ms (until the
    subscription has reached the talker's router); fails after ``timeout`` seconds."""
    samples = listener.declare_subscriber(key)
    publisher = talker.declare_publisher(key)
    deadline = time.monotonic() + timeout
    while (sample := samples.try_recv()) is None:
        assert time.monotonic() < deadline, f"nothing crossed the routers in {timeout:g} s"
        publisher.put(b"x")
        time.sleep(0.05)
    return sample
