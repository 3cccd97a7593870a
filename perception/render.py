"""Synthetic camera: RGB and thermal frames of the world truth, with labels (spec 000 §7, 002 §7).

A frame is built in layers, all from the camera's pinhole projection (:mod:`perception.pinhole`):

1. ground: a procedural world-fixed texture warped through the ground-plane homography, or sampled
   over a terrain (:mod:`perception.ground`); rays above the horizon see the sky;
2. fires: each fire cell (a ground polygon, or a square of ``size_m`` around a centre) is
   projected and filled: flame colours (red / orange / yellow) in RGB, ``temperature_K`` in the
   thermal image; the projected union is the true fire mask;
3. targets and occluders, far to near (painter's order): a ``"sphere"`` (a ball; apparent radius
   ``f·tan(asin(r/d))``) or a ``"disc"`` lying flat (its projected outline, an ellipse);
4. smoke: soft semi-transparent gray puffs, drawn over everything (opaque in RGB, faint in IR);
5. degradations (:mod:`perception.degradation`, applied by :mod:`perception.degrade`): noise, banding,
   speckles, failure.

Labels: for every target its pixel centre, depth, apparent radius, whether it is in view, the
fraction of its pixels left visible by occluders, and ``visible`` = in view, at least half
unoccluded and not behind dense smoke. Thermal frames are float32 Kelvin; RGB frames uint8 RGB.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache

import cv2
import numpy as np

from perception.degradation import Degradation
from perception.degrade import degrade
from perception.ground import GroundLayer, GroundTexture, ground_view
from perception.pinhole import PinholeView, as_view
from perception.scene import Fire, Occluder, RenderedFrame, Smoke, Target, TargetLabel, parse

__all__ = [
    "Target",
    "Occluder",
    "Fire",
    "Smoke",
    "TargetLabel",
    "RenderedFrame",
    "Projected",
    "default_ground",
    "ground_rgb",
    "painter_order",
    "project_object",
    "render_frame",
    "render_rgb",
    "render_thermal",
    "target_label",
]

NEAR_M = 0.05  # near clipping distance (chosen here)
SKY_RGB = (172, 198, 228)
SKY_K = 250.0
TARGET_WARMTH_K = 12.0  # default target temperature above ambient (chosen here: a running vehicle)
VISIBLE_FRACTION = 0.5  # a target at least this unoccluded counts as visible (chosen here)
SMOKE_OPAQUE = 0.5  # smoke alpha at the target centre above which it is hidden (chosen here)
SMOKE_IR = 0.1  # fraction of the smoke opacity seen by the thermal camera (chosen here)
_SHIFT = 4  # sub-pixel bits for OpenCV drawing
_ANGLES = np.linspace(0.0, 2 * math.pi, 24, endpoint=False)
_RIM = np.column_stack([np.cos(_ANGLES), np.sin(_ANGLES), np.zeros_like(_ANGLES)])  # a disc's unit rim, NED
_PAD = 32


@lru_cache(maxsize=4)
def default_ground(style: str | None = "terrain", resolution_m: float | None = None) -> GroundTexture:
    """A shared procedural ground, built once (~0.3 s): ``"terrain"`` at 0.25 m per texel or
    ``"tiles"`` at 0.05 m per texel (0.6 m tiles)."""
    style = style or "terrain"
    if resolution_m is None:
        resolution_m = 0.05 if style == "tiles" else 0.25
    return GroundTexture(style=style, resolution_m=resolution_m)


@lru_cache(maxsize=8)
def _flame_bank(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Flame colours (uint8 RGB) and a thermal flicker factor, padded for random offsets."""
    rng = np.random.default_rng(777)
    shape = (height + _PAD, width + _PAD)
    smooth = cv2.GaussianBlur(rng.random(shape, dtype=np.float32), (0, 0), 3.0)
    smooth = (smooth - smooth.mean()) / (smooth.std() + 1e-9)
    t = np.clip(0.58 + 0.2 * smooth + 0.15 * rng.standard_normal(shape), 0.0, 1.0)
    stops = np.array([0.0, 0.2, 0.45, 0.7, 0.88, 1.0])
    palette = np.array(
        [[85, 28, 14], [160, 35, 8], [225, 75, 15], [255, 150, 35], [255, 215, 95], [255, 245, 190]], float
    )  # charred / deep red / orange / yellow / white-hot (chosen here)
    rgb = np.dstack([np.interp(t, stops, palette[:, c]) for c in range(3)]).astype(np.uint8)
    flicker = (0.85 + 0.25 * t).astype(np.float32)
    rgb.setflags(write=False)
    flicker.setflags(write=False)
    return rgb, flicker


def _height_fn(terrain, ground_height: float) -> Callable:
    if terrain is None:
        return lambda n, e: np.full(np.shape(n), ground_height, float)
    return terrain.height if hasattr(terrain, "height") else terrain


def _fire_polygon(fire: Fire, height_fn: Callable) -> np.ndarray:
    region = np.asarray(fire.region, float)
    if region.ndim == 1:
        h = fire.size_m / 2.0
        region = region[:2] + np.array([[-h, -h], [-h, h], [h, h], [h, -h]])
    if region.shape[1] == 2:
        z = -np.asarray(height_fn(region[:, 0], region[:, 1]), float)
        region = np.column_stack([region, z])
    return region


def _clip_project(view: PinholeView, poly: np.ndarray) -> np.ndarray | None:
    """Project a world polygon, clipped to depth ≥ NEAR_M (Sutherland–Hodgman on one plane)."""
    cam = poly @ view.R.T + view.t
    inside = cam[:, 2] >= NEAR_M
    if inside.all():
        kept = cam
    elif not inside.any():
        return None
    else:
        out = []
        for i in range(len(cam)):
            a, b = cam[i], cam[(i + 1) % len(cam)]
            ia, ib = a[2] >= NEAR_M, b[2] >= NEAR_M
            if ia:
                out.append(a)
            if ia != ib:
                s = (NEAR_M - a[2]) / (b[2] - a[2])
                out.append(a + s * (b - a))
        kept = np.array(out)
    uvw = kept @ view.K.T
    return uvw[:, :2] / uvw[:, 2:]


def _fixed(points: np.ndarray) -> np.ndarray:
    pts = np.clip(points, -1e5, 1e5)
    return np.round((pts + 0.0) * (1 << _SHIFT)).astype(np.int32).reshape(-1, 1, 2)


@dataclass(frozen=True)
class Projected:
    """A target or occluder as the camera sees it, in frame pixels: its centre, depth, apparent radius and,
    for a disc, its projected outline (``None`` for a sphere: a circle of that radius)."""

    centre: np.ndarray
    depth: float
    radius: float
    outline: np.ndarray | None = None

    @cached_property
    def box(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)``: the pixels the object covers."""
        if self.outline is not None:
            (x0, y0), (x1, y1) = self.outline.min(axis=0), self.outline.max(axis=0)
            return float(x0), float(y0), float(x1), float(y1)
        u, v, r = float(self.centre[0]), float(self.centre[1]), self.radius
        return u - r, v - r, u + r, v + r

    def label_box(self, width: int, height: int) -> tuple[int, int, int, int]:
        """``(x0, y0, x1, y1)``, clipped to the frame: where its label counts the pixels left visible."""
        u, v = float(self.centre[0]), float(self.centre[1])
        r = int(math.ceil(self.radius)) + 2
        return max(0, int(u) - r), max(0, int(v) - r), min(width, int(u) + r + 1), min(height, int(v) + r + 1)

    def draw(self, img: np.ndarray, value, line: int = cv2.LINE_8, scale: float = 1.0, offset=(0, 0)) -> None:
        """Fill the object into ``img``, whose pixel ``p'`` is frame pixel ``p`` at ``p' = scale·p − offset``."""
        if self.outline is not None:
            cv2.fillPoly(img, [_fixed(self.outline * scale - offset)], value, line, _SHIFT)
        else:
            c = _fixed(self.centre * scale - offset).reshape(2)
            cv2.circle(
                img, (int(c[0]), int(c[1])), max(1, round(self.radius * scale * (1 << _SHIFT))), value, -1, line, _SHIFT
            )


def project_object(view: PinholeView, obj: Target) -> Projected | None:
    """The projection of a target or occluder; ``None`` behind the near plane or around the camera.

    A ``"sphere"`` has the apparent radius ``f·tan(asin(r/d))``; a ``"disc"`` lying flat is its projected
    outline (24 points of its rim, clipped to the near plane), with the radius of the circle of equal area."""
    pos = np.asarray(obj.position, float)
    cam = view.R @ pos + view.t
    dist = float(np.linalg.norm(cam))
    if cam[2] < NEAR_M or dist <= obj.radius_m:
        return None
    uvw = view.K @ cam
    centre = uvw[:2] / uvw[2]
    if obj.shape != "disc":
        return Projected(centre, float(cam[2]), view.focal * math.tan(math.asin(min(obj.radius_m / dist, 1.0))))
    poly = _clip_project(view, pos + obj.radius_m * _RIM)
    if poly is None:
        return None
    radius = float(np.sqrt(max(cv2.contourArea(poly.astype(np.float32)), 0.0) / math.pi))
    return Projected(centre, float(cam[2]), radius, poly)


def painter_order(view: PinholeView, targets: Sequence[Target], occluders: Sequence[Occluder] = ()) -> list[tuple]:
    """``(object, target index or -1 for an occluder)``, farthest from the camera first (painter's order)."""
    objects = [(t, i) for i, t in enumerate(targets)] + [(o, -1) for o in occluders]
    objects.sort(key=lambda item: -float(np.linalg.norm(np.asarray(item[0].position, float) - view.center)))
    return objects


def target_label(
    index: int,
    drawn: tuple[int, Projected] | None,
    ids: np.ndarray | None,
    width: int,
    height: int,
    alpha: np.ndarray | None = None,
    origin: tuple[int, int] = (0, 0),
) -> TargetLabel:
    """The label of target ``index``, drawn as object ``k`` (``drawn = (k, projection)``, ``None``: not drawn).

    ``ids`` holds the object number of every pixel of the frame region starting at pixel ``origin`` (it must
    cover the target's :meth:`Projected.label_box`; ``None``: no other object is drawn there); the visible
    fraction is the share of the target's own pixels there that still show it. ``alpha``: the frame's smoke
    opacity, or ``None``."""
    if drawn is None:
        return TargetLabel(index, (math.nan, math.nan), math.nan, 0.0, False, False, 0.0)
    k, shape = drawn
    u, v = float(shape.centre[0]), float(shape.centre[1])
    in_view = -0.5 <= u < width - 0.5 and -0.5 <= v < height - 0.5
    x0, y0, x1, y1 = shape.label_box(width, height)
    fraction = 0.0
    if x0 < x1 and y0 < y1:
        alone = np.zeros((y1 - y0, x1 - x0), np.uint8)
        shape.draw(alone, 1, cv2.LINE_8, offset=(x0, y0))
        total = int(np.count_nonzero(alone))
        ox, oy = origin
        seen = (
            total if ids is None else int(np.count_nonzero(ids[y0 - oy : y1 - oy, x0 - ox : x1 - ox][alone > 0] == k))
        )
        fraction = seen / total if total else 0.0
    smoky = alpha is not None and in_view and alpha[int(round(v)), int(round(u))] > SMOKE_OPAQUE
    visible = in_view and fraction >= VISIBLE_FRACTION and not smoky
    return TargetLabel(index, (u, v), shape.depth, shape.radius, in_view, visible, fraction)


def ground_rgb(layer: GroundLayer) -> np.ndarray:
    """The RGB image of a ground layer, sky filled in."""
    img = cv2.cvtColor(layer.rgbt, cv2.COLOR_RGBA2RGB)
    if layer.sky is not None:
        img[layer.sky] = SKY_RGB
    return img


def _smoke_alpha(view: PinholeView, puffs: list[Smoke], width: int, height: int):
    """Smoke opacity map (H×W float32, or ``None``) and the box ``(x0, y0, x1, y1)`` it covers."""
    alpha, box = None, [width, height, 0, 0]
    for puff in puffs:
        cam = view.R @ np.asarray(puff.position, float) + view.t
        if cam[2] < NEAR_M:
            continue
        uvw = view.K @ cam
        cu, cv = uvw[:2] / uvw[2]
        sigma = max(0.5, 0.5 * view.focal * puff.radius_m / float(np.linalg.norm(cam)))
        x0, x1 = max(0, int(cu - 3 * sigma)), min(width, int(cu + 3 * sigma) + 1)
        y0, y1 = max(0, int(cv - 3 * sigma)), min(height, int(cv + 3 * sigma) + 1)
        if x0 >= x1 or y0 >= y1:
            continue
        if alpha is None:
            alpha = np.zeros((height, width), np.float32)
        box = [min(box[0], x0), min(box[1], y0), max(box[2], x1), max(box[3], y1)]
        gx = np.exp(-0.5 * ((np.arange(x0, x1) - cu) / sigma) ** 2).astype(np.float32)
        gy = np.exp(-0.5 * ((np.arange(y0, y1) - cv) / sigma) ** 2).astype(np.float32)
        a = float(np.clip(puff.opacity, 0.0, 1.0)) * gy[:, None] * gx[None, :]
        region = alpha[y0:y1, x0:x1]
        region += a * (1.0 - region)  # alpha compositing: 1 − Π(1 − a_i)
    return alpha, tuple(box)


def render_frame(
    camera,
    width: int,
    height: int,
    targets: Sequence = (),
    fires: Sequence = (),
    smoke: Sequence = (),
    occluders: Sequence = (),
    ground: GroundTexture | None = None,
    ground_height: float = 0.0,
    terrain=None,
    degradation: Degradation | None = None,
    seed: int | np.random.Generator | None = None,
    rgb: bool = True,
    thermal: bool = True,
) -> RenderedFrame:
    """Render one RGB and/or thermal frame with labels.

    ``camera``: anything :func:`perception.pinhole.as_view` accepts (a 3×4 ``P``, ``(K, R, t)``,
    ``(pose, intrinsics)``, a pinhole ``project`` callable). ``targets``: :class:`Target` or tuples
    ``(position_ned, radius_m, rgb[, temperature_K])``; ``fires``: :class:`Fire` or
    ``(centre_or_polygon, size_m, temperature_K)``; ``smoke``: :class:`Smoke` or
    ``(position, radius_m[, opacity])``. ``ground``: a :class:`GroundTexture`, a style name or
    ``None`` (the shared terrain texture). ``terrain``: ``None`` (flat at ``ground_height``), an
    object with ``height(n, e)`` or a callable. ``seed`` makes the noise reproducible."""
    if width < 8 or height < 8:
        raise ValueError("image must be at least 8×8")
    targets, fires = parse(targets, Target), parse(fires, Fire)
    smoke, occluders = parse(smoke, Smoke), parse(occluders, Occluder)
    anchors = [t.position for t in targets] or [(0.0, 0.0, 0.0)]
    view = as_view(camera, anchors)
    ground = default_ground(ground) if ground is None or isinstance(ground, str) else ground
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    deg = Degradation() if degradation is None else degradation
    ambient = ground.ambient_K

    layer = ground_view(ground, view.P, width, height, ground_height, terrain).layer()
    img = ground_rgb(layer) if rgb else None
    th = ground.temperature(cv2.extractChannel(layer.rgbt, 3)) if thermal else None
    if layer.sky is not None and th is not None:
        th[layer.sky] = SKY_K

    fire_mask = np.zeros((height, width), bool)
    height_fn = _height_fn(terrain, ground_height)
    polys = [(p, f.temperature_K) for f in fires if (p := _clip_project(view, _fire_polygon(f, height_fn))) is not None]
    if polys:
        allpts = np.concatenate([p for p, _ in polys])
        x0, y0 = np.maximum(np.floor(allpts.min(axis=0)).astype(int) - 1, 0)
        x1, y1 = np.minimum(np.ceil(allpts.max(axis=0)).astype(int) + 2, (width, height))
        if x0 < x1 and y0 < y1:  # composite inside the fires' bounding box only
            heat = np.zeros((y1 - y0, x1 - x0), np.float32)
            for poly, temp in polys:
                cv2.fillPoly(heat, [_fixed(poly - (x0, y0))], float(temp), cv2.LINE_8, _SHIFT)
            box = heat > 0
            fire_mask[y0:y1, x0:x1] = box
            flame_rgb, flicker = _flame_bank(width, height)
            dy, dx = rng.integers(0, _PAD + 1, 2)
            if img is not None:
                np.copyto(img[y0:y1, x0:x1], flame_rgb[dy + y0 : dy + y1, dx + x0 : dx + x1], where=box[..., None])
            if th is not None:
                np.copyto(th[y0:y1, x0:x1], heat * flicker[dy + y0 : dy + y1, dx + x0 : dx + x1], where=box)

    objects = painter_order(view, targets, occluders)
    ids = np.zeros((height, width), np.uint16) if objects else None
    drawn: dict[int, tuple[int, Projected]] = {}
    for k, (obj, index) in enumerate(objects, start=1):
        shape = project_object(view, obj)
        if shape is None:
            continue
        temp = obj.temperature_K if obj.temperature_K is not None else ambient + (TARGET_WARMTH_K if index >= 0 else -3)
        values = (tuple(int(c) for c in obj.rgb), float(temp), k)
        for image, value, line in zip((img, th, ids), values, (cv2.LINE_AA, cv2.LINE_8, cv2.LINE_8), strict=True):
            if image is not None:
                shape.draw(image, value, line)
        if index >= 0:
            drawn[index] = (k, shape)
    if ids is not None and polys and x0 < x1 and y0 < y1:
        fire_mask[y0:y1, x0:x1] &= ids[y0:y1, x0:x1] == 0

    alpha, (sx0, sy0, sx1, sy1) = _smoke_alpha(view, smoke, width, height)
    if alpha is not None:  # blend inside the smoke's box only
        a = alpha[sy0:sy1, sx0:sx1]
        if img is not None:
            gray = np.float32(np.mean([p.gray for p in smoke]))
            patch = img[sy0:sy1, sx0:sx1]
            patch[:] = (patch * (1.0 - a[..., None]) + gray * a[..., None]).astype(np.uint8)
        if th is not None:
            patch = th[sy0:sy1, sx0:sx1]
            patch[:] = patch * (1.0 - SMOKE_IR * a) + ambient * SMOKE_IR * a

    labels = [target_label(i, drawn.get(i), ids, width, height, alpha) for i in range(len(targets))]

    if th is not None:
        th = cv2.GaussianBlur(th, (3, 3), 0.7)  # thermal optics are soft (chosen here)
    info = degrade(img, th, deg, rng, ambient)
    return RenderedFrame(img, th, labels, fire_mask, alpha, info)


def render_rgb(project, width: int, height: int, targets: Sequence = (), **kwargs) -> RenderedFrame:
    """RGB frame only (``.rgb``, labels, fire mask); keyword arguments as :func:`render_frame`."""
    return render_frame(project, width, height, targets, rgb=True, thermal=False, **kwargs)


def render_thermal(project, width: int, height: int, targets: Sequence = (), **kwargs) -> RenderedFrame:
    """Thermal frame only (``.thermal`` in kelvin, labels, fire mask); keyword arguments as :func:`render_frame`."""
    return render_frame(project, width, height, targets, rgb=False, thermal=True, **kwargs)
