"""``python -m mesh_sim.world``: the world process of a run — truth, clock, and the centralized oracle.

It publishes the targets' true states on ``sim/truth`` (agents' simulated sensors see the world only
through it) and runs the centralized references decentralized fusion is judged against
(:mod:`mesh_sim.oracle`): the *oracle*, one tracker that receives every agent's raw bearings without loss
(``sim/measurement/<agent>``) and associates them by their true labels — same models, same measurements,
no network — and the *in-flight oracle*, per agent the same filter holding only what could have reached
that agent through the radio graph by now.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import threading
import time
from pathlib import Path

import numpy as np

from agent.net import wire
from agent.net.fleet_key import read_key_file
from agent.net.keys import Keys
from agent.runtime import (
    LoopStats,
    SimClock,
    install_stop_handlers,
    run_steps,
    usage_error,
    wait_for_epoch,
    write_json,
)
from mesh_sim.fire import FireWorld
from mesh_sim.grid_oracle import GridOracle, grid_extent
from mesh_sim.oracle import InFlightOracle, Oracle
from mesh_sim.orbit_watch import OrbitWatch
from mesh_sim.particle_oracle import ParticleOracle
from mesh_sim.run_traces import RunTraces, finite_position
from mesh_sim.scenario import load
from mesh_sim.target_set import truth_snapshot
from perception.terrain import terrain_from_config
from tasking.assignment import AssignmentConfig

log = logging.getLogger("skymesh.world")

#: m: the separation counted when the scenario sets no ``[tasking] min_separation``: the assignment planner's default
REPORTED_SEPARATION = AssignmentConfig.min_separation
TRUTH_RATE_HZ = 10.0  # chosen here: agents extrapolate truth at constant velocity between snapshots


class World:
    """Truth publishing and the oracle, over any transport (Zenoh in a live run, the bus in lockstep)."""

    def __init__(self, scenario, transport, keys: Keys, fleet_key: bytes | None = None):
        self.scenario = scenario
        self.transport = transport
        self.keys = keys
        self.fleet_key = fleet_key  # signs the truth and checks the agents' messages (agent.net.fleet_key)
        self.oracle = Oracle(scenario.agent, imm=scenario.references.imm)
        self.in_flight = InFlightOracle(scenario.agent) if scenario.references.in_flight else None
        self.seq = 0
        self.uavs: dict[str, list] = {}  # agent -> last reported position (the radio's range check uses it)
        self.closest: tuple[float, int, int] = (math.inf, 0, 0)  # (closest pair distance, violations, samples)
        self.separation_limit = float(scenario.agent.tasking.get("min_separation", REPORTED_SEPARATION))
        tasking = scenario.agent.tasking
        radius = float(tasking.get("orbit_radius", AssignmentConfig.orbit_radius))
        self.orbits = OrbitWatch(radius, scenario.agent.agents) if tasking.get("orbit_slots", 1) > 1 else None
        self.now = 0.0
        self.traces = RunTraces()  # paths, track estimates and neighbour changes for the run's plots
        sc = scenario.agent
        terrain = terrain_from_config(sc.terrain)
        self.fire = None if scenario.fire is None else FireWorld(scenario.fire, terrain, sc.seed)
        self.grid_oracle = None if sc.grid is None else GridOracle(sc.grid, sc.area.as_tuple(), terrain,
                                                                   self.fire_truth)
        self.particles = (ParticleOracle(sc.tracking.particle_init, sc.seed)
                          if sc.tracking.initiation == "particles" else None)

    @staticmethod
    def subscriptions(keys: Keys) -> list[str]:
        return [keys.sim("measurement/*"), keys.telemetry("*"), keys.sim("grid_evidence/*"), keys.belief("grid", "*")]

    def publish_truth(self, t: float) -> None:
        self.now = t
        self.seq += 1
        self._note_separation()
        payload = {"targets": truth_snapshot(self.scenario.targets, t), "uavs": dict(self.uavs)}
        if self.orbits is not None:
            self.orbits.observe(t, self.uavs, payload["targets"])
        self.traces.on_truth(t, payload["targets"])
        if self.fire is not None:
            payload["fire"] = self.fire.payload(t)
            payload["decoys"] = [list(d) for d in self.scenario.decoys]
        env = wire.Envelope(kind="truth", origin="world", seq=self.seq, stamp=t, payload=payload)
        self.transport.publish(self.keys.sim("truth"), wire.encode(env, self.fleet_key))

    def absorb_measurements(self) -> None:
        """Feed every agent's raw bearings to the oracle, then score it."""
        for item in self.transport.drain():
            try:
                wire.check_encoding(item.encoding)
                env = wire.decode(item.data, expected_origin=self.keys.parse(item.key)[-1], key=self.fleet_key)
            except (wire.DecodeError, ValueError):
                self.oracle.rejected += 1
                continue
            if env.kind == "telemetry":
                self._note_position(env)
                self.traces.on_telemetry(env.origin, env.stamp, env.payload)
                if self.grid_oracle is not None and "alarms" in env.payload:
                    self.grid_oracle.add_located(env.origin, env.payload["alarms"])
            elif env.kind in ("grid", "grid_evidence"):
                if self.grid_oracle is not None:
                    (self.grid_oracle.add_grid if env.kind == "grid" else self.grid_oracle.add_evidence)(env)
            else:
                self.oracle.add(env, self.now)
                if self.in_flight is not None:
                    self.in_flight.add(env, self.now)
                if self.particles is not None and env.kind == "measurement":
                    self.particles.add(env)
        self.oracle.evaluate(self.scenario.targets)
        if self.in_flight is not None:
            self.in_flight.evaluate(self.scenario.targets, self.now)
        if self.grid_oracle is not None:
            self.grid_oracle.evaluate(self.now)
        if self.particles is not None:
            self.particles.evaluate(self.scenario.targets, self.now)

    def _note_separation(self) -> None:
        """The closest two UAVs have come, and how many (sample, pair) were closer than the scenario's
        ``[tasking] min_separation`` (:data:`REPORTED_SEPARATION` when it sets none)."""
        if len(self.uavs) < 2:
            return
        positions = np.array(list(self.uavs.values()))
        i, j = np.triu_indices(len(positions), k=1)
        distances = np.linalg.norm(positions[i] - positions[j], axis=1)
        closest, violations, samples = self.closest
        below = int(np.count_nonzero(distances < self.separation_limit))
        self.closest = (min(closest, float(distances.min())), violations + below,
                        samples + 1)

    def _note_position(self, env: wire.Envelope) -> None:
        position = finite_position(env.payload)
        if position is not None:
            self.uavs[env.origin] = position.tolist()

    def fire_truth(self, t: float) -> tuple[list[dict], list]:
        """The fire regions (none without a fire) and the decoys at ``t``: what fire maps are scored against."""
        regions = [] if self.fire is None else self.fire.fire_regions(t)
        return regions, [list(d) for d in self.scenario.decoys]

    def tick(self, t: float) -> None:
        self.publish_truth(t)
        self.absorb_measurements()

    def save_maps(self, folder: Path) -> None:
        """``fire_maps.npz`` in the run folder (only for a scenario with a grid)."""
        if self.grid_oracle is not None:
            if self.fire is None:
                return self.grid_oracle.save_maps(Path(folder) / "fire_maps.npz")
            extent = grid_extent(self.fire.origin, self.fire.shape, self.fire.config.cell)
            self.grid_oracle.save_maps(Path(folder) / "fire_maps.npz", self.fire.state_at(self.now), extent)

    def summary(self) -> dict:
        out = {"targets": self.oracle.evaluator.summary(), "late_measurements": self.oracle.late,
               "rejected": self.oracle.rejected, "traces": self.traces.summary()}
        closest, violations, samples = self.closest
        if samples:
            out["separation"] = {"closest_m": closest, "violations": violations, "samples": samples,
                                 "below_m": self.separation_limit}
        if self.orbits is not None:
            out["orbits"] = self.orbits.summary()
        if self.oracle.imm is not None:
            out["imm_targets"] = self.oracle.imm_evaluator.summary()
        if self.in_flight is not None:
            out["in_flight"] = self.in_flight.summary()
        if self.particles is not None:
            out["particles"] = self.particles.summary()
        if self.grid_oracle is not None:
            regions, decoys = self.fire_truth(self.now)
            out["grid"] = {**self.grid_oracle.summary(regions, decoys), "fire_regions": regions}
        return out


def main(argv=None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    p = argparse.ArgumentParser(prog="python -m mesh_sim.world")
    p.add_argument("--fleet", required=True)
    p.add_argument("--scenario", required=True)
    p.add_argument("--connect", action="append", default=[])
    p.add_argument("--zenoh-config")
    p.add_argument("--epoch", type=float, help="wall time of simulation t=0")
    p.add_argument("--speed", type=float, default=1.0)
    p.add_argument("--duration", type=float, required=True)
    p.add_argument("--out", default=".")
    p.add_argument("--parent-pid", type=int, help="exit when this process (the launcher) is gone")
    p.add_argument("--epoch-file", help="wait for the launcher to write the start time here (instead of --epoch)")
    p.add_argument("--ready-file", help="created once this process is ready (with --epoch-file)")
    p.add_argument("--fleet-key-file", help="file holding the fleet's HMAC key (agent.net.fleet_key)")
    args = p.parse_args(argv)
    from agent.net.zenoh_transport import ZenohTransport, load_config  # the live process only: lockstep needs no Zenoh

    try:
        scenario = load(args.scenario)
        config = load_config(args.connect, args.zenoh_config)
        fleet_key = read_key_file(args.fleet_key_file) if args.fleet_key_file else None
        keys = Keys(args.fleet)
        transport = ZenohTransport("world", keys, config, World.subscriptions(keys), liveliness=False)
    except (OSError, ValueError) as err:  # OSError: a scenario file that cannot be read, no router (SessionError)
        return usage_error("world", err)
    world = World(scenario, transport, keys, fleet_key)
    stop = threading.Event()
    install_stop_handlers(stop)
    epoch = args.epoch if args.epoch is not None else time.time()
    if args.epoch_file:
        epoch = wait_for_epoch(args.epoch_file, args.ready_file or f"{args.epoch_file}.world", stop, args.parent_pid)
    started = time.time()
    try:
        stats = LoopStats() if epoch is None else run_steps(
            world.tick, SimClock(epoch, args.speed), 1.0 / TRUTH_RATE_HZ, args.duration + 1.0, stop, args.parent_pid
        )
    finally:
        transport.close()
    write_json(Path(args.out) / "oracle.json", {**world.summary(), "wall_s": time.time() - started, **stats.as_dict()})
    world.save_maps(Path(args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
