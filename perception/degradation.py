"""Image degradations of the synthetic camera (thesis 000 §2.2–2.4 and §7 "synthetic noise injector").

The thesis camera sends analog video over a radio link. Interference shows as rapidly alternating
horizontal dark and light bands (Figure 2-4), sometimes with lines torn sideways, and as transient
blobs that last one or two frames; a failed link shows no picture at all. :class:`Degradation`
describes these effects and :func:`perception.degrade.degrade` applies them in place to an RGB frame
(uint8) and its thermal companion (float Kelvin) with one banding pattern, as one radio link would. This
module holds only the descriptions (no OpenCV): a scenario's camera settings are read without loading it.

* Gaussian sensor noise (``noise_sigma`` gray levels, ``thermal_noise_K`` Kelvin), drawn from a
  cached noise bank at a random offset (fast; adjacent frames are uncorrelated);
* banding: with probability ``banding_prob`` per frame, a window of rows (``banding_coverage`` of
  the height) is cut into bands of ``banding_rows`` rows (at 480 lines, scaled to the frame),
  alternately brightened and darkened by up to ``banding_amplitude`` gray levels, some shifted
  sideways by up to ``banding_shift_px`` pixels (at 640 columns);
* speckles: ``Poisson(speckle_rate)`` random dark or light blobs per frame, radius
  ``speckle_radius_px`` (at 640 columns), independent from frame to frame;
* ``failed``: ``"snow"`` (analog no-signal static with banding), ``"black"`` (no picture) or
  ``"banding"`` (nothing but bands): the scene is replaced.

Every default is chosen here; the thesis gives no numbers for its noise.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CONDITIONS", "FAILURE_MODES", "Degradation", "DegradationInfo"]

FAILURE_MODES = ("snow", "black", "banding")


@dataclass(frozen=True)
class Degradation:
    """Noise, banding, speckles and failure of one camera link (defaults chosen here)."""

    noise_sigma: float = 2.0
    thermal_noise_K: float = 0.1
    banding_prob: float = 0.0
    banding_amplitude: float = 110.0
    banding_rows: tuple[int, int] = (3, 14)
    banding_coverage: tuple[float, float] = (0.3, 1.0)
    banding_shift_px: int = 24
    banding_thermal_K: float = 25.0
    speckle_rate: float = 0.0
    speckle_radius_px: tuple[float, float] = (4.0, 12.0)
    failed: str | None = None
    degrade_thermal: bool = True

    def __post_init__(self) -> None:
        if self.failed is not None and self.failed not in FAILURE_MODES:
            raise ValueError(f"failed must be None or one of {FAILURE_MODES}, got {self.failed!r}")
        if not 0.0 <= self.banding_prob <= 1.0:
            raise ValueError("banding_prob must be in [0, 1]")
        if self.noise_sigma < 0 or self.thermal_noise_K < 0 or self.speckle_rate < 0:
            raise ValueError("noise levels and speckle rate must be non-negative")


@dataclass(frozen=True)
class DegradationInfo:
    """What was applied to one frame (for labelling and tests)."""

    banding: bool = False
    speckles: int = 0
    failed: str | None = None


#: The video conditions detectors are evaluated under: clean, the two transient defects and the three
#: failure modes (thesis 000 §2.4); shared by the detection benchmark and the detector tests.
CONDITIONS: dict[str, Degradation] = {
    "clean": Degradation(),
    "banding": Degradation(banding_prob=0.5),
    "speckles": Degradation(speckle_rate=2.0),
    "snow": Degradation(failed="snow"),
    "black": Degradation(failed="black"),
    "bands": Degradation(failed="banding"),
}
