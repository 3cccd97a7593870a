"""What the synthetic camera is asked to draw, and what it reports back (see :mod:`perception.render`).

Scene elements are plain frozen dataclasses in world NED coordinates (metres, kelvin); each may
also be given as a tuple of its fields in order, e.g. ``((n, e, d), radius_m, (r, g, b))``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from perception.degradation import DegradationInfo

__all__ = ["Target", "Occluder", "Fire", "Smoke", "TargetLabel", "RenderedFrame", "parse"]


@dataclass(frozen=True)
class Target:
    """A target: NED ``position`` (its centre), ``radius_m``, RGB colour, optional temperature."""

    position: tuple[float, float, float]
    radius_m: float
    rgb: tuple[int, int, int] = (200, 20, 20)
    temperature_K: float | None = None
    shape: str = "sphere"  # "sphere" (ball) or "disc" (flat, horizontal)


@dataclass(frozen=True)
class Occluder(Target):
    """Something that hides targets (a tree canopy, a roof): drawn like a target, never labelled."""

    rgb: tuple[int, int, int] = (46, 84, 40)


@dataclass(frozen=True)
class Fire:
    """A burning cell: ``region`` is a centre (2,) / (3,) with square side ``size_m``, or a ground
    polygon (N, 2) / (N, 3) in NED (height from the terrain when only north/east are given)."""

    region: Sequence
    size_m: float = 10.0
    temperature_K: float = 800.0


@dataclass(frozen=True)
class Smoke:
    """A smoke puff centred at ``position`` (NED) with radius ``radius_m`` and peak ``opacity``."""

    position: tuple[float, float, float]
    radius_m: float
    opacity: float = 0.7
    gray: int = 178


@dataclass(frozen=True)
class TargetLabel:
    """Truth for one target in one frame (pixel coordinates, u right, v down)."""

    index: int
    center_px: tuple[float, float]
    depth: float
    radius_px: float
    in_view: bool
    visible: bool
    visible_fraction: float


@dataclass
class RenderedFrame:
    """One rendered view: images, labels and what degraded it.

    The labels are the geometric truth: with a failed camera (``failed`` set) the targets are
    still labelled visible although the image shows nothing of them."""

    rgb: np.ndarray | None
    thermal: np.ndarray | None
    targets: list[TargetLabel]
    fire_mask: np.ndarray
    smoke_alpha: np.ndarray | None = None
    info: DegradationInfo = field(default_factory=DegradationInfo)

    @property
    def failed(self) -> str | None:
        return self.info.failed

    def visible_centers(self) -> np.ndarray:
        """``(n, 2)`` pixel centres of the visible targets (the detection truth)."""
        return np.array([t.center_px for t in self.targets if t.visible], float).reshape(-1, 2)

    def ignore_regions(self) -> np.ndarray:
        """``(n, 3)`` rows ``(u, v, radius_px)`` of targets drawn but not counted as visible (cut by
        the frame edge, occluded, in smoke): a detection there is neither a hit nor a false alarm."""
        rows = [(*t.center_px, t.radius_px) for t in self.targets if not t.visible and np.isfinite(t.depth)]
        return np.array(rows, float).reshape(-1, 3)


def parse(items, cls) -> list:
    """Scene elements given as instances of ``cls`` or as tuples of its fields."""
    return [item if isinstance(item, cls) else cls(*item) for item in items or ()]
