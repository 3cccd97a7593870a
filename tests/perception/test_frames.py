"""Bad input: every malformed frame gives a FrameError with the right reason, and no detector crashes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from perception.blobs import ColorBlobDetector, DarkBlobDetector
from perception.fire_segmentation import FireSegmenter
from perception.frames import FRAME_ERROR_REASONS, FrameError, RejectCounter, check_frame
from perception.persistence import PersistentDetector
from perception.quality import VideoQuality

RGB = np.full((48, 64, 3), 200, np.uint8)


@pytest.mark.parametrize(
    ("frame", "kwargs", "reason"),
    [
        (None, {}, "empty"),
        (np.zeros((0, 64, 3), np.uint8), {}, "empty"),
        (b"", {}, "empty"),
        (np.zeros((24, 32, 3), np.uint8), {"expected_shape": (48, 64, 3)}, "wrong_shape"),
        (np.zeros((48, 64, 3), np.uint8), {"expected_shape": (48, 64)}, None),
        (np.zeros((48, 64), np.uint8), {"expected_shape": (48, 64, 3)}, "wrong_shape"),
        (np.zeros((2, 48, 64, 3), np.uint8), {}, "wrong_shape"),
        (np.zeros((48, 64, 2), np.uint8), {}, "wrong_shape"),
        (np.zeros(64, np.uint8), {}, "wrong_shape"),
        (np.zeros((48, 64, 3), np.float64), {}, "wrong_dtype"),
        (np.zeros((48, 64, 3), np.int32), {}, "wrong_dtype"),
        ("not an image", {}, "wrong_dtype"),
        ([[1, 2], [3, 4]], {}, "wrong_dtype"),
        (b"\x89PNG\r\n\x1a\n garbage", {}, "corrupt"),
        (np.full((48, 64), np.nan, np.float32), {"dtypes": (np.float32,)}, "corrupt"),
        (np.where(np.eye(48, 64) > 0, np.inf, 300.0).astype(np.float32), {"dtypes": (np.float32,)}, "corrupt"),
    ],
)
def test_check_frame_reasons(frame, kwargs, reason):
    if reason is None:
        assert check_frame(frame, **kwargs) is frame
        return
    with pytest.raises(FrameError) as info:
        check_frame(frame, **kwargs)
    assert info.value.reason == reason
    assert reason in str(info.value)


def test_encoded_frames_are_decoded_to_rgb():
    bgr = np.zeros((8, 8, 3), np.uint8)
    bgr[..., 2] = 255  # red in OpenCV's BGR order
    ok, png = cv2.imencode(".png", bgr)
    assert ok
    frame = check_frame(png.tobytes(), expected_shape=(8, 8, 3))
    assert frame[0, 0].tolist() == [255, 0, 0]


def test_unknown_reason_is_refused():
    with pytest.raises(ValueError, match="unknown frame error reason"):
        FrameError("odd")


def _histogram_segmenter() -> FireSegmenter:
    image = np.zeros((16, 16, 3), np.uint8)
    image[:8] = (255, 140, 20)
    image[8:] = (60, 110, 40)
    mask = np.zeros((16, 16), bool)
    mask[:8] = True
    return FireSegmenter("histogram", expected_shape=(16, 16, 3)).fit([image], [mask])


BAD_RGB = [
    (None, "empty"),
    (np.zeros((0, 0, 3), np.uint8), "empty"),
    (np.zeros((24, 32, 3), np.uint8), "wrong_shape"),
    (np.zeros((48, 64, 3, 1), np.uint8), "wrong_shape"),
    (np.zeros((48, 64, 3), np.float32), "wrong_dtype"),
    (object(), "wrong_dtype"),
    (b"\x00\x01\x02 not a jpeg", "corrupt"),
]


@pytest.mark.parametrize(
    "make",
    [
        lambda: ColorBlobDetector(expected_shape=(48, 64, 3)),
        lambda: DarkBlobDetector(expected_shape=(48, 64, 3)),
        lambda: PersistentDetector(DarkBlobDetector(expected_shape=(48, 64, 3))),
    ],
    ids=["colour", "dark", "persistent"],
)
def test_detectors_count_bad_frames_and_never_crash(make):
    detector = make()
    for frame, reason in BAD_RGB:
        result = detector.detect(frame)
        assert result.error == reason
        assert result.detections == []
    assert detector.rejected.as_dict() == {"empty": 2, "wrong_shape": 2, "wrong_dtype": 2, "corrupt": 1}
    assert detector.rejected.total == len(BAD_RGB)
    good = detector.detect(np.full((48, 64, 3), 200, np.uint8))
    assert good.ok and good.error is None


def test_fire_segmenters_count_bad_frames():
    thermal = FireSegmenter("threshold", expected_shape=(16, 16))
    bad_thermal = [
        (None, "empty"),
        (np.full((16, 16), np.nan, np.float32), "corrupt"),
        (np.zeros((8, 8), np.float32), "wrong_shape"),
        (np.zeros((16, 16, 3), np.float32), "wrong_shape"),
        (np.zeros((16, 16), np.int64), "wrong_dtype"),
    ]
    for frame, reason in bad_thermal:
        result = thermal.segment(frame)
        assert result.mask is None and result.error == reason
    assert thermal.rejected.total == len(bad_thermal)
    assert thermal.segment(np.full((16, 16), 900.0, np.float32)).mask.all()

    visual = _histogram_segmenter()
    for frame, reason in [
        (None, "empty"),
        (np.zeros((16, 16), np.uint8), "wrong_shape"),
        (np.zeros((16, 16, 3), np.float32), "wrong_dtype"),
        (b"xx", "corrupt"),
    ]:
        assert visual.segment(frame).error == reason
    assert visual.rejected.total == 4


def test_video_quality_counts_bad_frames_as_worst_quality():
    quality = VideoQuality(k=4)
    for frame in (None, np.zeros((10, 10, 3), np.float64), b"junk"):
        report = quality.update(frame)
        assert report.d == 1.0 and report.error is not None
    assert quality.failed
    assert quality.rejected.as_dict() == {"empty": 1, "wrong_shape": 0, "wrong_dtype": 1, "corrupt": 1}


def test_reject_counter_reports_every_reason():
    counter = RejectCounter()
    counter.record(FrameError("corrupt"))
    assert counter["corrupt"] == 1 and counter.total == 1
    assert set(counter.as_dict()) == set(FRAME_ERROR_REASONS)
