"""Measured detection / false-alarm rates of the synthetic camera and the detectors.

``python -m mesh_sim.bench.detection_rates [--frames 60] [--width 640 --height 480]`` prints two tables:
target detection per detector and condition (clean, banding in half the frames, transient speckles,
three kinds of failed camera) with the video-quality D(t); and per-pixel fire segmentation (thermal
threshold, visual histogram trained on other frames).

Milliseconds per frame of the renderer, these detectors and geolocation, at 320×240 and 640×480 with
one OpenCV thread and with the default count, are measured by ``skymesh bench perception``
(:mod:`mesh_sim.bench.perception`), which replaced the timing table that used to be printed here.
"""

from __future__ import annotations

from collections.abc import Sequence

from perception.degradation import CONDITIONS, Degradation
from perception.evaluation import detection_rates, segmentation_rates, sequence


def _detector_rows(n_frames: int, width: int, height: int) -> list[tuple]:
    from perception.blobs import ColorBlobDetector, DarkBlobDetector
    from perception.persistence import PersistentDetector
    from perception.quality import VideoQuality

    radius = 10.0 * width / 640.0
    rows = []
    for cond, deg in CONDITIONS.items():
        scenes = {
            "colour (red balls, terrain)": sequence(
                n_frames, width, height, "terrain", target_rgb=(210, 25, 30), degradation=deg, seed=5, thermal=False
            ),
            "dark (tiles floor)": sequence(n_frames, width, height, "tiles", degradation=deg, seed=3, thermal=False),
        }
        for scene, frames in scenes.items():
            images = [f.rgb for f in frames]
            base = ColorBlobDetector if scene.startswith("colour") else DarkBlobDetector
            quality = VideoQuality()
            reports = [quality.update(im) for im in images]
            for name, det, warm in (
                ("raw, no band rejection", base(reject_banding=False), 0),
                ("raw", base(), 0),
                ("+ persistent filter", PersistentDetector(base()), 3),
            ):
                r = detection_rates(det, images, frames, radius, warmup=warm)
                rows.append((scene, name, cond, r.p_d, r.fa_per_frame, r.p_fa_frame, reports[-1].D, reports[-1].failed))
    return rows


def _fire_rows(n_frames: int, width: int, height: int) -> list[tuple]:
    from perception.fire_segmentation import FireSegmenter

    train = sequence(
        8, width, height, "terrain", n_targets=0, n_fires=4, smoke_opacity=0.6, seed=11, speed_m_per_frame=3.0
    )
    visual = FireSegmenter("histogram").fit([f.rgb for f in train], [f.fire_mask for f in train])
    thermal = FireSegmenter("threshold")
    rows = []
    conditions = {"clean": (Degradation(), 0.0), "smoke 0.6": (Degradation(), 0.6)}
    conditions.update({k: (v, 0.0) for k, v in CONDITIONS.items() if k != "clean"})
    for cond, (deg, smoke) in conditions.items():
        frames = sequence(
            n_frames,
            width,
            height,
            "terrain",
            n_targets=2,
            target_rgb=(210, 25, 30),
            n_fires=4,
            smoke_opacity=smoke,
            degradation=deg,
            seed=12,
            speed_m_per_frame=3.0,
        )
        masks = [f.fire_mask for f in frames]
        for name, seg, images in (
            ("thermal threshold", thermal, [f.thermal for f in frames]),
            ("visual histogram", visual, [f.rgb for f in frames]),
        ):
            r = segmentation_rates(seg, images, masks)
            rows.append((name, cond, r.p_d, r.p_f, r.iou, r.observed))
    return rows


def main(argv: Sequence[str] | None = None) -> None:
    import argparse

    parser = argparse.ArgumentParser(
        description="Measured detection and fire-segmentation rates of the synthetic camera and detectors"
    )
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    args = parser.parse_args(argv)
    print(
        f"Target detection, {args.frames} frames per row, {args.width}x{args.height}, match radius "
        f"{10 * args.width / 640:.0f} px (persistent: first 3 frames not scored)"
    )
    print(
        f"{'scene':30s} {'detector':24s} {'condition':18s} {'P_D':>6s} {'FA/frame':>9s} {'P(FA)':>6s} "
        f"{'D(t)':>6s} failed"
    )
    for scene, name, cond, p_d, fa, pfa, D, failed in _detector_rows(args.frames, args.width, args.height):
        print(f"{scene:30s} {name:24s} {cond:18s} {p_d:6.3f} {fa:9.3f} {pfa:6.3f} {D:6.3f} {failed}")
    print(f"\nFire segmentation (per pixel), {args.frames} test frames; histogram trained on 8 other frames")
    print(f"{'segmenter':20s} {'condition':18s} {'P_D':>6s} {'P_F':>8s} {'IoU':>6s} {'observed':>8s}")
    for name, cond, p_d, p_f, iou, observed in _fire_rows(args.frames, args.width, args.height):
        print(f"{name:20s} {cond:18s} {p_d:6.3f} {p_f:8.4f} {iou:6.3f} {observed:8.3f}")


if __name__ == "__main__":
    main()
