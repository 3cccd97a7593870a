"""skymesh estimation mathematics: beliefs, filters and decentralized fusion. numpy/scipy only."""

from fusion.channel_filter import ChannelFilter, Policy, Received
from fusion.covariance_intersection import ci, fast_ci
from fusion.gaussian import Gaussian, UninformativeBeliefError
from fusion.trajectory import Trajectory, TrajectoryModel

__all__ = [
    "ChannelFilter",
    "Gaussian",
    "Policy",
    "Received",
    "Trajectory",
    "TrajectoryModel",
    "UninformativeBeliefError",
    "ci",
    "fast_ci",
]
