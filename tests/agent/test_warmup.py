"""An agent process's warm-up (agent/warmup.py): it does the one-time work, once per process, and leaves no trace
in what the real agents then do."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import cv2

import agent.warmup as warmup
from mesh_sim.scenario import load
from perception.degrade import _rgb_noise

LOCKSTEP = """
import json, sys, tempfile
from pathlib import Path
from mesh_sim.lockstep import run_lockstep
from mesh_sim.scenario import load
scenario = load("default", agents=3, duration=6, seed=4)
if sys.argv[1] == "warm":
    from agent.warmup import warm_up
    assert warm_up(scenario.agent)
fleet = run_lockstep(scenario, Path(tempfile.mkdtemp()))["fleet"]
print(json.dumps({k: v for k, v in fleet.items() if isinstance(v, (int, float))}))
"""


def test_agents_stepped_after_a_warm_up_do_exactly_what_they_do_in_a_cold_process():
    """The throwaway agent shares nothing with the real ones that changes them (no counter, no random state), and
    OpenCV on one thread draws the same frames: a lockstep run's figures agree to the last digit."""
    runs = {mode: subprocess.run([sys.executable, "-c", LOCKSTEP, mode], capture_output=True, text=True, timeout=300,
                                 check=True).stdout.splitlines()[-1] for mode in ("cold", "warm")}
    cold, warm = json.loads(runs["cold"]), json.loads(runs["warm"])
    assert cold["rmse"] > 0 and cold == warm


def test_a_warm_up_fills_the_camera_caches_runs_opencv_on_one_thread_and_happens_once(monkeypatch):
    monkeypatch.setattr(warmup, "_warm", False)
    threads = cv2.getNumThreads()
    _rgb_noise.cache_clear()
    try:
        assert warmup.warm_up(load("default", agents=2).agent, steps=2) is True
        assert _rgb_noise.cache_info().currsize >= 1  # the noise banks of the camera's frames
        assert cv2.getNumThreads() == 1
        assert warmup.warm_up(load("default", agents=2).agent) is False  # once per process (and its forks)
    finally:
        cv2.setNumThreads(threads)


def test_a_mavlink_vehicle_is_not_built_to_warm_up(monkeypatch):
    """Building it would connect to an autopilot: the scenario's MAVLink agents warm up in their own first steps."""
    monkeypatch.setattr(warmup, "_warm", False)
    scenario = load("default", agents=2).agent
    mavlink = replace(scenario, vehicle={**scenario.vehicle, "kind": "mavlink", "url": "udpin:127.0.0.1:1"})
    assert warmup.warm_up(mavlink) is False and warmup._warm is False
