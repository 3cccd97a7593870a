"""Persistent Object Filter (thesis 000 §2.3) with fixes (a)–(e), on hand-made detection streams."""

from __future__ import annotations

import numpy as np
import pytest

from perception.detection import Detection, DetectionResult
from perception.persistence import PersistentDetector, PersistentObjectFilter


def blob(u: float, v: float, area: float = 100.0) -> Detection:
    return Detection((u, v), area, (int(u) - 5, int(v) - 5, 10, 10))


def run(filt: PersistentObjectFilter, stream) -> list[list]:
    return [filt.update_frame(frame) for frame in stream]


def test_transient_blobs_are_never_reported():
    filt = PersistentObjectFilter()  # min_count 3
    # A one-frame blob, then a two-frame blob elsewhere, each among empty frames.
    stream = [[blob(50, 50)], [], [], [blob(200, 100)], [blob(201, 101)], [], [], []]
    assert all(out == [] for out in run(filt, stream))
    assert filt.objects == []  # and they are forgotten


def test_target_is_confirmed_then_kept_while_hidden():
    filt = PersistentObjectFilter(max_count=8, min_count=3)
    out = run(filt, [[blob(100, 100)]] * 2)
    assert out == [[], []]
    assert len(filt.update_frame([blob(100, 100)])) == 1  # (c): reported at exactly min_count
    run(filt, [[blob(100, 100)]] * 5)  # count saturates at max_count = 8
    assert filt.objects[0].frame_count == 8
    hidden = run(filt, [[]] * 5)  # hidden by noise for 5 frames: 8 -> 3, still reported
    assert all(len(q) == 1 for q in hidden)
    assert filt.update_frame([]) == []  # 6th hidden frame: below min_count
    assert len(filt.objects) == 1
    run(filt, [[]] * 2)
    assert filt.objects == []  # count reached 0: removed


def test_fix_a_new_objects_survive_their_first_frame():
    filt = PersistentObjectFilter()
    filt.update_frame([blob(10, 10)])
    assert len(filt.objects) == 1 and filt.objects[0].frame_count == 1 and filt.objects[0].found_this_frame


def test_fix_b_moving_target_is_followed():
    path = [[blob(100 + 6 * k, 80 + 3 * k)] for k in range(30)]  # 6.7 px / frame
    filt = PersistentObjectFilter(max_distance=10.0)
    out = run(filt, path)
    assert {o.id for q in out[2:] for o in q} == {0}  # one identity all along
    # As written (no position update), the object stays where it was first seen and the moving
    # target keeps spawning new objects.
    literal = PersistentObjectFilter(max_distance=10.0, update=False, velocity_gain=0.0)
    ids, reported = set(), 0
    for frame in path:
        reported += len(literal.update_frame(frame))
        ids |= {o.id for o in literal.objects}
    assert len(ids) > 10 and reported < 10


def test_fix_d_one_detection_per_object_per_frame():
    filt = PersistentObjectFilter()
    filt.update_frame([blob(100, 100)])
    filt.update_frame([blob(102, 100), blob(99, 101)])  # two detections inside the gate
    counts = sorted(o.frame_count for o in filt.objects)
    assert counts == [1, 2]  # the nearest one matched (count 2), the other became a new object
    assert filt.objects[0].x == (99, 101)
    # Detections added in this frame are not candidates for other detections of the same frame.
    fresh = PersistentObjectFilter()
    fresh.update_frame([blob(10, 10), blob(12, 10)])
    assert [o.frame_count for o in fresh.objects] == [1, 1]


def test_fix_e_all_expiring_objects_are_removed():
    filt = PersistentObjectFilter()
    filt.update_frame([blob(30 * k + 10, 40) for k in range(6)])
    assert len(filt.objects) == 6
    filt.update_frame([])
    assert filt.objects == []


def test_area_gates():
    filt = PersistentObjectFilter(max_area_ratio=2.0)
    filt.update_frame([blob(50, 50, 100.0)])
    filt.update_frame([blob(51, 50, 250.0)])  # 2.5× larger: not the same object
    assert [(o.id, o.frame_count) for o in filt.objects] == [(1, 1)]
    thesis = PersistentObjectFilter(max_area_ratio=None, max_area_diff=50.0)  # C_A
    thesis.update_frame([blob(50, 50, 100.0)])
    thesis.update_frame([blob(51, 50, 140.0)])
    assert len(thesis.objects) == 1 and thesis.objects[0].frame_count == 2


def test_hidden_moving_target_is_predicted():
    filt = PersistentObjectFilter()
    for k in range(6):
        filt.update_frame([blob(100 + 8 * k, 200.0)])
    for k in range(6, 9):  # hidden for three frames
        (obj,) = filt.update_frame([])
        assert obj.x[0] == pytest.approx(100 + 8 * k, abs=1.0) and obj.x[1] == pytest.approx(200.0)
    (obj,) = filt.update_frame([blob(100 + 8 * 9, 200.0)])
    assert obj.id == 0 and obj.found_this_frame


def test_blind_rows_keep_counts_for_a_while():
    filt = PersistentObjectFilter(max_count=8, min_count=3, max_blind=4)
    run(filt, [[blob(100, 100)]] * 3)
    blind = lambda u, v: True  # noqa: E731
    for _ in range(4):
        assert len(filt.update_frame([], blind=blind)) == 1
    assert filt.objects[0].frame_count == 3  # not observed: kept
    filt.update_frame([], blind=blind)  # the 5th blind frame counts as a miss
    assert filt.objects[0].frame_count == 2


def test_object_leaving_the_frame_is_dropped():
    filt = PersistentObjectFilter()
    run(filt, [[Detection((3.0, 50.0), 60.0, (0, 45, 8, 10))]] * 4)
    assert len(filt.confirmed()) == 1
    assert filt.update_frame([], frame_size=(640, 480)) == []
    assert filt.objects == []


def test_parameter_validation():
    with pytest.raises(ValueError):
        PersistentObjectFilter(min_count=5, max_count=3)
    with pytest.raises(ValueError):
        PersistentObjectFilter(max_distance=0.0)


class Scripted:
    """A detector that replays a script of results."""

    def __init__(self, results):
        self.results = list(results)
        self.rejected = None

    def detect(self, frame):
        return self.results.pop(0)


def test_persistent_detector_passes_errors_and_treats_rejected_frames_as_unobserved():
    mask = np.zeros((48, 64), np.uint8)
    good = [DetectionResult([blob(30, 20)], mask=mask) for _ in range(3)]
    bad = [DetectionResult(error="corrupt") for _ in range(12)]
    det = PersistentDetector(Scripted(good + bad))
    outs = [det.detect(None) for _ in range(15)]
    assert [len(o.detections) for o in outs[:3]] == [0, 0, 1]
    assert outs[3].error == "corrupt" and len(outs[3].detections) == 1  # kept while unobserved
    assert all(len(o.detections) == 0 for o in outs[-3:])  # but a camera that stays bad forgets it
