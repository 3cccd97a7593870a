"""Particle beliefs: two bearing-only UAVs each see a ray; fused, their particle sets find the target.

A single bearing leaves the target anywhere along a line, a belief no Gaussian describes well. A particle set
([Merino2007] Ch. 5, :class:`fusion.particles.ParticleSet`) starts uniform over the area and is re-weighted by
each bearing's likelihood, resampled and jittered when its effective size falls ([Merino2007] §5.3.3,
:func:`fusion.particles.sir_update`). Each UAV here takes ten bearings from its own spot, so each set is a
narrow wedge along its ray. Fusing the two sets by Alg. 5.2 (:func:`fusion.particle_fusion.fuse_bayes`:
``bel_i bel_j / bel_ij``, with the uniform prior as the common information ``bel_ij``) keeps the particles
where the wedges cross — what one filter holding both UAVs' bearings finds.

Run: ``python docs/gallery/particle_belief_from_bearings.py``
"""

import numpy as np

from fusion.measurement import wrap_angle
from fusion.particle_fusion import UniformBox, fuse_bayes
from fusion.particles import sir_update

AREA = UniformBox(lower=[-100.0, -100.0], upper=[100.0, 100.0])
TARGET = np.array([30.0, -20.0])
UAVS = {"uav0": np.array([-90.0, -90.0]), "uav1": np.array([-80.0, 90.0])}
SIGMA, LOOKS, PARTICLES = np.radians(3.0), 10, 2000


def bearing_log_likelihood(sensor: np.ndarray, z: float):
    """The log-likelihood of azimuth ``z`` from ``sensor`` at every particle (Gaussian angular noise)."""
    def log_likelihood(states: np.ndarray) -> np.ndarray:
        predicted = np.arctan2(states[:, 1] - sensor[1], states[:, 0] - sensor[0])
        return -0.5 * (wrap_angle(z - predicted) / SIGMA) ** 2
    return log_likelihood


def describe(name: str, particles) -> None:
    error = np.linalg.norm(particles.mean() - TARGET)
    spread = np.sqrt(np.linalg.eigvalsh(particles.cov()))
    print(f"{name:>12}: error {error:6.2f} m, spread {spread[0]:5.2f} m x {spread[1]:6.2f} m")


def main() -> None:
    rng = np.random.default_rng(5)
    beliefs = {name: AREA.sample(rng, PARTICLES) for name in UAVS}
    central = AREA.sample(rng, PARTICLES)
    for _ in range(LOOKS):
        for name, sensor in UAVS.items():
            z = np.arctan2(*(TARGET - sensor)[::-1]) + SIGMA * rng.standard_normal()
            likelihood = bearing_log_likelihood(sensor, z)
            beliefs[name] = sir_update(beliefs[name], likelihood(beliefs[name].states), rng).particles
            central = sir_update(central, likelihood(central.states), rng).particles
    for name, particles in beliefs.items():
        describe(f"{name} alone", particles)
    fused = fuse_bayes(beliefs["uav0"], beliefs["uav1"], AREA, rng)
    describe("fused", fused)
    describe("centralized", central)


if __name__ == "__main__":
    main()
