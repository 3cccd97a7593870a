"""On a ring of agents, naive fusion becomes overconfident; covariance intersection does not.

Four agents on a ring measure a parked target's position and exchange beliefs with their two neighbours. On
a loop a belief comes back to its sender through the other side, so adding every received belief as if it
were new evidence (``naive``) counts the same measurements again and again: the covariance shrinks far below
the real error. A channel filter cannot help either (``exact``: it knows only what one link shares, not what
arrived around the loop). Covariance intersection ([JulierUhlmann1997b]; ``ci``, and ``hybrid``, which uses it
on every edge that lies on a loop, so here on every edge) is consistent whatever the correlation.

Consistency is measured as in the runtime: the average NEES over independent trials (ANEES) against the 95 %
χ² interval for that many samples ([BarShalom2001] §5.4.2). Above the interval: overconfident.

Run: ``python docs/gallery/covariance_intersection_on_a_ring.py``
"""

import numpy as np
from scipy.stats import chi2

from fusion import Gaussian
from fusion.measurement import PositionMeasurement
from fusion.network import FilterNetwork

AGENTS, ROUNDS, TRIALS, SIGMA, DIM = 4, 4, 100, 3.0, 2
RING = [(i, (i + 1) % AGENTS) for i in range(AGENTS)]
TARGET = np.array([40.0, -25.0])


def anees(policy: str, rng: np.random.Generator) -> float:
    """Agent 0's NEES after ``ROUNDS`` rounds of measuring and exchanging, averaged over ``TRIALS`` trials and
    divided by the dimension (1 for a consistent estimator)."""
    sensor = PositionMeasurement(DIM, SIGMA**2 * np.eye(DIM), spatial_dims=DIM)
    nees = []
    for _ in range(TRIALS):
        ring = FilterNetwork(AGENTS, RING, Gaussian.zeros(DIM), policy=policy)
        for _ in range(ROUNDS):
            for agent in range(AGENTS):
                z = TARGET + SIGMA * rng.standard_normal(DIM)
                ring.apply(agent, lambda belief, z=z: belief.update(sensor.H, sensor.R_inv, z))
            ring.exchange()
        nees.append(ring.beliefs[0].nees(TARGET))
    return float(np.mean(nees)) / DIM


def main() -> None:
    low, high = chi2.ppf([0.025, 0.975], DIM * TRIALS) / (DIM * TRIALS)
    print(f"ANEES of agent 0 on a ring of {AGENTS}, {TRIALS} trials; consistent within [{low:.2f}, {high:.2f}]")
    for policy in ("naive", "exact", "ci", "hybrid"):
        value = anees(policy, np.random.default_rng(7))  # the same measurements for every policy
        verdict = "overconfident" if value > high else "consistent" if value >= low else "conservative"
        print(f"  {policy:>6}: ANEES {value:6.2f}  {verdict}")


if __name__ == "__main__":
    main()
