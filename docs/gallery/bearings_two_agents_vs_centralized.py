"""Two UAVs locate a target from bearings alone, and end up with exactly the centralized estimate.

Each UAV flies its own circle and measures only the azimuth to a parked target, so on its own it learns the
target's direction well and its range badly. Each keeps an information filter (:class:`fusion.Gaussian`,
updated by the extended information filter, [Merino2007] (3.52)) and after every step the two exchange
their beliefs over a link. The link's channel filter (:class:`fusion.ChannelFilter`, [Merino2007] (3.39)-(3.42))
subtracts what the two already share, so nothing is counted twice, and on a tree of agents (two agents and one
link is the smallest) each agent's belief is then the belief of a centralized filter that received every
bearing.

The centralized filter here applies each step's bearings together, linearised at its mean before the step —
what each agent does with its own bearing — so the two agree to rounding error, not only approximately.

Run: ``python docs/gallery/bearings_two_agents_vs_centralized.py``
"""

import numpy as np

from fusion import Gaussian
from fusion.information_filter import eif_update
from fusion.measurement import Bearing2D
from fusion.network import FilterNetwork

TARGET = np.array([60.0, 40.0])  # north, east [m]
CENTRES = [np.array([0.0, 0.0]), np.array([120.0, -30.0])]  # each UAV's circle
RADIUS, SIGMA, STEPS = 30.0, np.radians(2.0), 40


def uav_position(uav: int, step: int) -> np.ndarray:
    angle = 0.05 * step + np.pi * uav
    return CENTRES[uav] + RADIUS * np.array([np.cos(angle), np.sin(angle)])


def bearing_update(sensor, z, linearise_at):
    """The EIF update of one bearing, linearised at a given point (a function of the belief)."""
    return lambda belief: eif_update(belief, Bearing2D(2, sensor, SIGMA), z, linearization_point=linearise_at)


def main() -> None:
    rng = np.random.default_rng(4)
    prior = Gaussian.from_moments([50.0, 20.0], np.diag([50.0**2, 50.0**2]))
    team = FilterNetwork(2, [(0, 1)], prior, policy="exact")
    alone = [prior, prior]  # the same UAVs without the link
    central = prior
    for step in range(STEPS):
        sensors = [uav_position(uav, step) for uav in range(2)]
        bearings = [Bearing2D(2, s, SIGMA).h(TARGET)[0] + SIGMA * rng.standard_normal() for s in sensors]
        central_mean = central.mean
        for uav in range(2):
            z = np.array([bearings[uav]])
            team.apply(uav, bearing_update(sensors[uav], z, team.beliefs[uav].mean))
            alone[uav] = bearing_update(sensors[uav], z, alone[uav].mean)(alone[uav])
            central = bearing_update(sensors[uav], z, central_mean)(central)
        team.exchange()

    print(f"after {STEPS} steps of one bearing per UAV (σ = 2°):")
    for uav in range(2):
        error = np.linalg.norm(team.beliefs[uav].mean - TARGET)
        alone_error = np.linalg.norm(alone[uav].mean - TARGET)
        print(f"  uav{uav}: error {error:5.2f} m with the link, {alone_error:6.2f} m alone")
    print(f"  centralized filter: error {np.linalg.norm(central.mean - TARGET):5.2f} m")
    gap = max(np.max(np.abs(b.mean - central.mean)) for b in team.beliefs)
    print(f"  largest difference between an agent's mean and the centralized mean: {gap:.1e} m")
    print(f"decentralized equals centralized: {gap < 1e-6}")


if __name__ == "__main__":
    main()
