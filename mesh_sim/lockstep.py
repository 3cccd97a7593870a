"""The lockstep harness: a whole run in one process, deterministic, many times faster than real time.

The same :class:`~agent.agent.Agent` class as a live run, over an in-memory bus
(:class:`~agent.net.bus.InMemoryBus`) instead of Zenoh, stepped on simulation time instead of the wall
clock: only the transport and the clock differ (DESIGN.md §4). At each step the world publishes the
truth, every agent steps in turn, and the oracle absorbs the bearings; the observer, when enabled,
logs the same messages it would receive live.

It writes the same run folder as ``skymesh run`` (``metrics.json``, per-process metrics, plots and,
with ``rerun="save"``, ``recording.rrd``), so results are compared like with like.
"""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Callable
from pathlib import Path

from agent.agent import Agent
from agent.net.bus import InMemoryBus
from agent.net.keys import Keys
from agent.runtime import write_json
from agent.sensors.video_source import VideoSource
from mesh_sim import results
from mesh_sim.scenario import Scenario
from mesh_sim.world import World


def run_lockstep(scenario: Scenario, run_dir: Path, rerun: str = "off", cameras: dict | None = None,
                 advance: Callable[[float], None] = lambda t: None) -> dict:
    """Run ``scenario`` to completion in this process; returns the merged metrics. ``cameras`` maps an agent
    name to an OpenCV video source (file, device, URL) that replaces its synthetic camera; ``advance(t)`` is
    called after each step with its simulation time (a progress bar: :mod:`mesh_sim.sim_progress`)."""
    sc = scenario.agent
    keys = Keys(f"{scenario.name}-{uuid.uuid4().hex[:8]}")
    bus = InMemoryBus()
    cameras = cameras or {}
    unknown = set(cameras) - {f"uav{i}" for i in range(sc.agents)}
    if unknown:
        raise ValueError(f"--camera names no agent of this run: {sorted(unknown)}")
    sources = {name: VideoSource(source) for name, source in cameras.items()}  # ValueError if one cannot open
    agents = [
        Agent(f"uav{i}", i, sc, bus.endpoint(f"uav{i}", keys.agent_subscriptions(sc.senders_to(f"uav{i}"))), keys,
              seed=sc.seed * 1000 + i, camera=sources.get(f"uav{i}"), lockstep=True)
        for i in range(sc.agents)
    ]
    world = World(scenario, bus.endpoint("world", World.subscriptions(keys)), keys)
    observer, watch = None, None
    if rerun == "save":
        from mesh_sim.observer import Observer

        observer = Observer(keys, recording_id=keys.root.rsplit("/", 1)[-1])
        observer.save(str(run_dir / "recording.rrd"))
        watch = bus.endpoint("observer", [keys.telemetry("*"), f"{keys.root}/belief/**", keys.sim("truth")])
    started = time.time()
    steps = int(round(sc.duration / sc.step))
    for k in range(steps + 1):
        t = k * sc.step
        world.publish_truth(t)
        for agent in agents:
            agent.step(t)
        world.absorb_measurements()
        if observer is not None:
            for item in watch.drain():
                observer.handle(item)
        advance(t)
    if observer is not None:
        observer.close()
    for agent in agents:
        agent.close()
    wall = time.time() - started
    for agent in agents:
        write_json(run_dir / f"agent-{agent.id}.json", {
            "pid": os.getpid(), **agent.metrics(), "deadline_misses": 0, "skipped_steps": 0,
            "cpu_per_step_ms": 1e3 * wall / max(1, agent.steps * len(agents)),
        })
    write_json(run_dir / "oracle.json", {**world.summary(), "wall_s": wall})
    world.save_maps(run_dir)
    return results.collect(run_dir, scenario, "completed", speed=sc.duration / max(wall, 1e-9))
