"""An agent process's one-time work, done before simulation time 0 instead of in its first steps.

An agent's first step in a fresh process costs far more than the next ones: a camera draws its noise banks
(:func:`perception.degrade._rgb_noise`, cached for the process), and libraries build what they build on first
use. Measured (16 camera agents of ``default``, one process each, every one starting at time 0 on 2 cores):
~170 ms of CPU for the first step against ~8 ms for the next, so the fleet's first steps queued behind each other
for 0.5-0.9 s, and 24 of the 26 late steps of a 30 s run were in its first 1.2 s.

:func:`warm_up` does that work once per process, before the agent reports ready: it steps a throwaway agent of
the same scenario over an in-memory bus, then drops it. The fork server (:mod:`agent.forkserver`) warms up before
it forks, so its children share the result (the banks are read-only, so copy-on-write never copies them) and
start warm; a process started on its own (``python -m agent``, the namespace test bed) warms up itself.

It also runs OpenCV on one thread in an agent process (``cv2.setNumThreads(1)``), as the launcher runs BLAS on one
(``OPENBLAS_NUM_THREADS=1``): the agents of a machine share its cores, and OpenCV's worker threads only add their
hand-over. Measured (16 camera agents in lockstep, 20 s): 8.5-8.8 ms of CPU per agent step with OpenCV's default
two threads, 7.1-7.3 ms with one. Its results do not depend on the thread count.
"""

from __future__ import annotations

import sys

from agent.config import AgentScenario

#: steps of the throwaway agent (1 s at 5 Hz): its first pays the one-time work, the others what a second
#: or third step still builds (chosen here)
STEPS = 5

_warm = False  # this process has warmed up (a forked child inherits it)


def _one_thread_for_opencv() -> None:
    """``cv2.setNumThreads(1)`` if this process has imported OpenCV (a bearing agent never does: not imported
    here either)."""
    cv2 = sys.modules.get("cv2")
    if cv2 is not None:
        cv2.setNumThreads(1)


def warm_up(scenario: AgentScenario, steps: int = STEPS) -> bool:
    """Step a throwaway agent of ``scenario`` ``steps`` times over an in-memory bus and drop it, once per process,
    and run OpenCV on one thread from then on (called after the process's own agent is built, so that OpenCV is
    imported when that agent uses it). Returns False when no agent was stepped: this process (or the one it was
    forked from) has warmed up, or the scenario flies a MAVLink vehicle, which is not built here (it would connect
    to an autopilot)."""
    global _warm
    if not _warm and scenario.vehicle.get("kind") != "mavlink":
        from agent.agent import Agent
        from agent.net.bus import InMemoryBus
        from agent.net.keys import Keys

        keys = Keys("warm-up")
        agent = Agent("uav0", 0, scenario, InMemoryBus().endpoint("uav0", keys.agent_subscriptions()), keys, seed=0)
        _one_thread_for_opencv()
        try:
            for k in range(steps):
                agent.step(k * scenario.step)
        finally:
            agent.close()
        _warm = True
        return True
    _one_thread_for_opencv()
    return False
