"""Shared by the vehicle model tests: random setpoint plans and a helper that flies them."""

from __future__ import annotations

import numpy as np
from hypothesis import settings
from hypothesis import strategies as st

from agent.vehicles.base import Setpoint

TOL = 1e-9

coord = st.floats(-300.0, 300.0)
depth = st.floats(-150.0, 0.0)


@st.composite
def setpoints(draw, min_radius: float = 1.0):
    position = np.array([draw(coord), draw(coord), draw(depth)])
    speed = draw(st.none() | st.floats(0.5, 30.0))
    orbit = None
    if draw(st.booleans()):
        orbit = (
            np.array([draw(coord), draw(coord)]),
            draw(st.floats(min_radius, 200.0)),
            draw(st.sampled_from([1, -1])),
        )
    velocity = draw(st.none() | st.tuples(st.floats(-30.0, 30.0), st.floats(-30.0, 30.0)))  # a feed-forward
    duration = draw(st.integers(1, 40))
    return Setpoint(position, speed=speed, orbit=orbit, velocity=velocity), duration


def fly(vehicle, plan, dt):
    """Fly ``plan`` [(setpoint, steps)] and return the list of states (initial included)."""
    states = [vehicle.state()]
    for setpoint, steps in plan:
        vehicle.set_setpoint(setpoint)
        for _ in range(steps):
            vehicle.step(dt)
            states.append(vehicle.state())
    return states


#: What the hard-limit tests of both models fly: 40 plans of 1-5 random setpoints, at one of four agent steps.
LIMIT_EXAMPLES = settings(max_examples=40, deadline=None)
plans = st.lists(setpoints(), min_size=1, max_size=5)
agent_steps = st.sampled_from([0.05, 0.2, 0.5, 1.0])
