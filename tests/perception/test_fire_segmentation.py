"""Fire segmentation (Merino App. B): thermal threshold and a trained colour histogram."""

from __future__ import annotations

import numpy as np
import pytest

from perception.evaluation import segmentation_rates
from perception.fire_segmentation import FireSegmenter, _min_error_threshold, pixel_rates
from tests.perception.scenes import fires


def visual_segmenter() -> FireSegmenter:
    train = fires("clean", seed=11, smoke=0.6, n_frames=8)  # flights, fires and ground not used for testing
    return FireSegmenter("histogram").fit([f.rgb for f in train], [f.fire_mask for f in train])


def test_min_error_threshold_hand_checked():
    scores = np.array([1.0, 2.0, 3.0, 4.0])
    pos = np.array([0.0, 0.0, 1.0, 1.0])
    neg = np.array([1.0, 1.0, 0.0, 0.0])
    assert _min_error_threshold(scores, pos, neg) == pytest.approx(2.5)
    assert _min_error_threshold(scores, pos, neg, prefer=2.2) == pytest.approx(2.2)
    assert _min_error_threshold(scores, pos, neg, prefer=10.0) == pytest.approx(3.0)
    assert _min_error_threshold(scores, pos, neg, prefer=10.0) < 3.0
    # Overlap: the count-weighted error decides (one fire pixel at 2 is outweighed by 5 background).
    assert _min_error_threshold(scores, np.array([0, 1, 1, 1.0]), np.array([5, 5, 0, 0.0])) == pytest.approx(2.5)


def test_pixel_rates():
    truth = np.zeros((4, 4), bool)
    truth[:2] = True
    pred = np.zeros((4, 4), bool)
    pred[1:3] = True
    assert pixel_rates(pred, truth) == pytest.approx((0.5, 0.5, 4 / 12))


def test_thermal_threshold_segmentation():
    test = fires("clean", seed=12)
    r = segmentation_rates(FireSegmenter("threshold"), [f.thermal for f in test], [f.fire_mask for f in test])
    assert r.iou >= 0.9 and r.p_d >= 0.95 and r.p_f <= 0.005


def test_thermal_threshold_can_be_fitted():
    train = fires("clean", seed=11, smoke=0.6, n_frames=8)
    seg = FireSegmenter("threshold").fit([f.thermal for f in train], [f.fire_mask for f in train])
    hottest_ground = max(float(f.thermal[~f.fire_mask].max()) for f in train)
    assert hottest_ground < seg.threshold_K < 650.0
    p_d, p_f = seg.train_rates
    assert p_d > 0.95 and p_f < 0.001


def test_visual_histogram_trained_on_other_frames():
    seg = visual_segmenter()
    assert seg.train_rates[0] > 0.9 and seg.train_rates[1] < 0.01
    clean = fires("clean", seed=12)
    r = segmentation_rates(seg, [f.rgb for f in clean], [f.fire_mask for f in clean])
    assert r.iou >= 0.85 and r.p_d >= 0.9 and r.p_f <= 0.01
    smoky = fires("clean", seed=12, smoke=0.6)
    r = segmentation_rates(seg, [f.rgb for f in smoky], [f.fire_mask for f in smoky])
    assert r.iou >= 0.75 and r.p_f <= 0.01


def test_visual_roc_is_monotone_and_contains_the_operating_point():
    seg = visual_segmenter()
    test = fires("clean", seed=12, smoke=0.6)
    thresholds, p_d, p_f = seg.roc([f.rgb for f in test], [f.fire_mask for f in test])
    assert np.all(np.diff(thresholds) > 0)
    assert np.all(np.diff(p_d) <= 1e-12) and np.all(np.diff(p_f) <= 1e-12)
    i = np.searchsorted(thresholds, seg.tau)
    assert p_d[max(i - 1, 0)] > 0.8 and p_f[min(i, len(p_f) - 1)] < 0.01


def test_banding_rows_are_reported_blind_not_burning():
    seg = visual_segmenter()
    frames = fires("banding", seed=12)
    naive = FireSegmenter("histogram", reject_banding=False)
    naive.log_lr = seg.log_lr
    naive.set_tau(seg.tau)
    loud = segmentation_rates(naive, [f.rgb for f in frames], [f.fire_mask for f in frames])
    quiet = segmentation_rates(seg, [f.rgb for f in frames], [f.fire_mask for f in frames])
    assert loud.p_f > 0.02  # bright bands turn straw and clay into flame colours
    assert quiet.p_f <= 0.01 and quiet.iou >= 0.85 and quiet.observed < 1.0
    thermal = segmentation_rates(FireSegmenter("threshold"), [f.thermal for f in frames], [f.fire_mask for f in frames])
    assert thermal.iou >= 0.85


@pytest.mark.parametrize("condition", ["snow", "black", "bands"])
def test_failed_camera_reports_no_fire(condition):
    seg = visual_segmenter()
    frames = fires(condition, seed=12)
    for f in frames:
        assert not FireSegmenter("threshold").segment(f.thermal).mask.any()
        assert not seg.segment(f.rgb).mask.any()


def test_fit_and_use_errors():
    with pytest.raises(RuntimeError):
        FireSegmenter("histogram").segment(np.zeros((4, 4, 3), np.uint8))
    image = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(ValueError, match="both"):
        FireSegmenter("histogram").fit([image], [np.zeros((4, 4), bool)])
    with pytest.raises(ValueError):
        FireSegmenter("histogram").fit([image], [])
    with pytest.raises(ValueError):
        FireSegmenter("magic")
    with pytest.raises(ValueError):
        FireSegmenter("histogram", bins=30)
