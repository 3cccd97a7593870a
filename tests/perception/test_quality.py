"""Video-quality measure D(t) (thesis 000 §2.4, Eqs. 2.1–2.4)."""

from __future__ import annotations

import numpy as np
import pytest

from perception.quality import EDGE_KERNEL, VideoQuality, banding_measure, blind_rows, noisy_rows
from tests.perception.scenes import dark_targets, red_balls


def test_kernel_is_the_reconstructed_prewitt():
    np.testing.assert_array_equal(EDGE_KERNEL, [[1, 1, 1], [0, 0, 0], [-1, -1, -1]])


def test_d_hand_checked_on_a_step():
    # Top two rows 0, bottom two rows 255: rows 1 and 2 respond with |3·0 − 3·255| = 765 in each
    # of 4 columns; rows 0 and 3 see replicated borders and respond 0.
    step = np.zeros((4, 4), np.uint8)
    step[2:] = 255
    assert banding_measure(step) == pytest.approx(8 * 765 / (16 * 765))
    assert banding_measure(step.T.copy()) == 0.0  # a vertical edge gives nothing
    assert banding_measure(np.full((4, 4), 77, np.uint8)) == 0.0


def test_running_mean_over_the_last_k_frames():
    quality = VideoQuality(k=3, work_size=None, blank_std=0.0, blank_mean=0.0)
    flat = np.full((8, 8), 100, np.uint8)
    bands = np.tile(np.repeat([40, 200], 2), 2)[:, None].repeat(8, axis=1).astype(np.uint8)
    d_bands = banding_measure(bands)
    assert d_bands > 0.3
    seq = [flat, bands, bands, flat, flat, flat]
    expected = [0, d_bands / 2, 2 * d_bands / 3, 2 * d_bands / 3, d_bands / 3, 0]
    for frame, D in zip(seq, expected, strict=True):
        assert quality.update(frame).D == pytest.approx(D)


def test_blank_frames_are_failures():
    quality = VideoQuality(k=2)
    report = quality.update(np.zeros((240, 320, 3), np.uint8))
    assert report.blank and report.d == 1.0 and report.failed


def test_intermittent_banding_degrades_without_failing():
    quality = VideoQuality()
    reports = [quality.update(f.rgb) for f in dark_targets("banding")]
    banded = [r.d for r, f in zip(reports, dark_targets("banding"), strict=True) if f.info.banding]
    clean = [r.d for r, f in zip(reports, dark_targets("banding"), strict=True) if not f.info.banding]
    assert min(banded) > 2 * max(clean)
    assert quality.good_level < quality.D < quality.threshold
    assert 0.0 < quality.weight() < 1.0


def test_noisy_rows_mark_the_banding_episode_only():
    for frame in dark_targets("banding")[:12]:
        gray = frame.rgb.mean(axis=2).astype(np.uint8)
        rows = blind_rows(gray)
        assert rows.shape == (480,)
        if frame.info.banding:
            assert rows.mean() > 0.2
        else:
            assert not rows.any()
    for frame in red_balls("clean")[:5]:
        assert not noisy_rows(frame.rgb[::2, ::2, 1].copy()).any()


def test_validation():
    with pytest.raises(ValueError):
        VideoQuality(k=0)
    assert VideoQuality().D == 0.0 and not VideoQuality().failed
