"""Labelled synthetic scenes shared by the detector tests (rendered once per test session)."""

from __future__ import annotations

from functools import cache

from perception.degradation import CONDITIONS
from perception.evaluation import sequence

N_FRAMES = 40
FAILED = ("snow", "black", "bands")


@cache
def red_balls(condition: str, seed: int = 5):
    """Three 0.5 m red balls on grass / soil seen from 30 m, camera flying north (640×480)."""
    return sequence(
        N_FRAMES,
        640,
        480,
        "terrain",
        target_rgb=(210, 25, 30),
        degradation=CONDITIONS[condition],
        seed=seed,
        thermal=False,
    )


@cache
def dark_targets(condition: str, seed: int = 3):
    """Three 0.5 m dark balls on the light tiled floor of thesis 000, from 30 m (640×480)."""
    return sequence(N_FRAMES, 640, 480, "tiles", degradation=CONDITIONS[condition], seed=seed, thermal=False)


@cache
def fires(condition: str, seed: int, smoke: float = 0.0, n_frames: int = 10):
    """Four burning cells (2–5 m, 650–1000 K) and two red balls, RGB + thermal (640×480)."""
    return sequence(
        n_frames,
        640,
        480,
        "terrain",
        n_targets=2,
        target_rgb=(210, 25, 30),
        n_fires=4,
        smoke_opacity=smoke,
        degradation=CONDITIONS[condition],
        seed=seed,
        speed_m_per_frame=3.0,
    )
