"""Procedural ground texture and its projection into a camera image (part of the synthetic camera).

The texture lives in world coordinates (NED north/east, metres): a periodic RGB image with a
fourth channel that encodes the surface temperature, precomputed once and kept as a mip-map
pyramid. A frame is made by sampling it through the camera geometry:

* flat ground at height ``h0`` (NED ``z = −h0``): the ground plane maps to the image by the
  homography ``G = [p₁ p₂ (−h0·p₃ + p₄)]`` (columns of the 3×4 projection ``P``), so the whole
  ground layer is one ``cv2.warpPerspective`` of the texture — exact for a pinhole camera;
* any terrain ``h(n, e)``: a coarse grid of rays is intersected with the surface by fixed-point
  iteration on the ray parameter, the resulting ground coordinates are interpolated to full
  resolution and the texture is sampled with ``cv2.remap`` (approximate: no self-occlusion of the
  terrain, which is fine for the gentle hills of ``perception.terrain``).

Pixels whose ray does not meet the ground (above the horizon) are reported as sky.
The texture's pixel ``(col, row)`` is the world point ``(n, e) = origin + (row, col)·resolution``.

:func:`ground_view` works out how one frame sees the ground (:class:`FlatGround`: the mip level, the
homography, the horizon; :class:`TerrainGround`); its ``layer(A, size)`` draws the frame, or any image whose
pixels are the frame's under a pixel map ``A`` — a window (``A`` a shift), the whole view at a lower resolution
(``A`` a scale), as :func:`perception.roi_render.render_roi` draws. An image whose pixels stand for the means of
k×k frame pixels samples the frame's mip level averaged over the texels they cover (:func:`texel_box`,
:meth:`GroundTexture.boxed`): the box filter of area averaging rather than the wider Gaussian of the next level.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from perception.shared_arrays import digest, shared_arrays

__all__ = ["GroundTexture", "GroundLayer", "FlatGround", "TerrainGround", "ground_view"]

_SMALLEST_LEVEL = 64  # texels: the pyramid's last level


def _periodic_noise(size: int, cells: int, rng: np.random.Generator) -> np.ndarray:
    """Smooth value noise in [0, 1] on a ``size×size`` torus with ``cells`` random nodes per side."""
    grid = rng.random((cells, cells)).astype(np.float32)
    pad = 2
    big = np.pad(grid, pad, mode="wrap")
    step = size // cells
    up = cv2.resize(big, (big.shape[1] * step, big.shape[0] * step), interpolation=cv2.INTER_CUBIC)
    return up[pad * step : pad * step + size, pad * step : pad * step + size]


def _fractal(size: int, rng: np.random.Generator, base_cells: int, octaves: int) -> np.ndarray:
    out = np.zeros((size, size), np.float32)
    amp, total, cells = 1.0, 0.0, base_cells
    for _ in range(octaves):
        if size % cells or cells > size:
            break
        out += amp * _periodic_noise(size, cells, rng)
        total += amp
        amp *= 0.5
        cells *= 2
    return out / total


class GroundTexture:
    """A periodic procedural ground: RGB plus a temperature channel, with a mip-map pyramid.

    ``style="terrain"``: grass / dry grass / bare soil patches (outdoor search, fire scenes).
    ``style="tiles"``: a light tiled floor with faint grout lines (the RAVEN lab floor of thesis
    000, against which dark targets are detected). The texture covers ``size_px·resolution_m``
    metres and repeats. Temperature: ``ambient_K + (byte − 128)·thermal_span_K / 255``."""

    def __init__(
        self,
        style: str = "terrain",
        resolution_m: float = 0.25,
        size_px: int = 1024,
        origin_ne: tuple[float, float] = (0.0, 0.0),
        ambient_K: float = 295.0,
        thermal_span_K: float = 30.0,
        tile_size_m: float = 0.6,
        seed: int = 0,
    ):
        if style not in ("terrain", "tiles"):
            raise ValueError(f"unknown ground style {style!r}")
        if size_px < _SMALLEST_LEVEL or size_px & (size_px - 1):
            raise ValueError("size_px must be a power of two ≥ 64")
        self.style, self.resolution_m, self.size_px = style, float(resolution_m), int(size_px)
        self.origin_ne = (float(origin_ne[0]), float(origin_ne[1]))
        self.ambient_K, self.thermal_span_K = float(ambient_K), float(thermal_span_K)
        # The pyramid is the same in every process that asks for these parameters: one copy per machine, mapped
        # from a cache file (perception.shared_arrays: 21 MB at 1024 texels, shared by all the camera agents).
        # Its name also holds what builds it: this module's source and the numpy and OpenCV versions.
        name = "ground-" + digest(style, self.resolution_m, size_px, tile_size_m, seed, Path(__file__).read_bytes(),
                                  np.__version__, cv2.__version__)
        count = int(math.log2(size_px // _SMALLEST_LEVEL)) + 1
        self.levels: list[np.ndarray] = shared_arrays(name, count, lambda: self._pyramid(seed, tile_size_m))
        self._boxed: dict[tuple[int, int], np.ndarray] = {}

    def _pyramid(self, seed: int, tile_size_m: float) -> list[np.ndarray]:
        """Mip levels of 2×2-tiled copies of the texture: any footprint smaller than one period fits in one
        window."""
        rng = np.random.default_rng(seed)
        tile = self._terrain(rng) if self.style == "terrain" else self._tiles(rng, tile_size_m)
        levels = []
        while True:
            levels.append(np.tile(tile, (2, 2, 1)))
            if tile.shape[0] <= _SMALLEST_LEVEL:
                return levels
            # Periodic pyrDown: pad with wrapped texels so the tile stays seamless at every level.
            padded = np.pad(tile, ((8, 8), (8, 8), (0, 0)), mode="wrap")
            tile = np.ascontiguousarray(cv2.pyrDown(padded)[4:-4, 4:-4])

    @property
    def period_m(self) -> float:
        return self.size_px * self.resolution_m

    def _terrain(self, rng: np.random.Generator) -> np.ndarray:
        n = self.size_px
        dry = _fractal(n, rng, 4, 5)
        soil = _fractal(n, rng, 8, 4)
        clay_field = _fractal(n, rng, 8, 4)
        grain = rng.random((n, n), dtype=np.float32)
        grass = np.array([62, 104, 44], np.float32)
        straw = np.array([150, 140, 84], np.float32)
        dirt = np.array([112, 88, 64], np.float32)
        a = np.clip((dry - 0.35) / 0.3, 0.0, 1.0)[..., None]
        rgb = (1 - a) * grass + a * straw
        b = np.clip((soil - 0.62) / 0.08, 0.0, 1.0)[..., None]
        rgb = (1 - b) * rgb + b * dirt
        clay = np.array([168, 96, 52], np.float32)  # orange-brown clay: fire-like hues on the ground
        c = np.clip((clay_field - 0.66) / 0.06, 0.0, 1.0)[..., None]
        rgb = (1 - c) * rgb + c * clay
        rgb *= (0.85 + 0.3 * grain)[..., None]
        temp = 128 + 70 * (a[..., 0] - 0.5) + 60 * b[..., 0] + 12 * (grain - 0.5)
        return np.dstack([np.clip(rgb, 0, 255), np.clip(temp, 0, 255)]).astype(np.uint8)

    def _tiles(self, rng: np.random.Generator, tile_size_m: float) -> np.ndarray:
        n = self.size_px
        count = max(1, round(n * self.resolution_m / tile_size_m))
        edges = np.floor(np.arange(count) * n / count).astype(int)
        line = np.zeros(n, bool)
        line[edges] = True
        grout = line[:, None] | line[None, :]
        mottle = _fractal(n, rng, 16, 3)
        grain = rng.random((n, n), dtype=np.float32)
        gray = 212 + 14 * (mottle - 0.5) + 6 * (grain - 0.5)
        gray = np.where(grout, gray - 28, gray)
        rgb = np.dstack([gray, gray * 0.99, gray * 0.96])
        temp = 128 + 4 * (mottle - 0.5)
        return np.dstack([np.clip(rgb, 0, 255), np.clip(temp, 0, 255)]).astype(np.uint8)

    def boxed(self, level: int, box: int) -> np.ndarray:
        """Mip level ``level`` averaged over ``box``×``box`` texels (``cv2.INTER_AREA``), built once: the box
        filter of area averaging, for images whose pixels are means of finer pixels (:func:`texel_box`), where the
        next mip level would apply the wider Gaussian of ``pyrDown``."""
        key = (level, box)
        if key not in self._boxed:
            tex = self.levels[level]
            boxed = cv2.resize(tex, (tex.shape[1] // box, tex.shape[0] // box), interpolation=cv2.INTER_AREA)
            boxed.setflags(write=False)
            self._boxed[key] = boxed
        return self._boxed[key]

    def level_for(self, gsd_m: float) -> int:
        """Mip level whose texel is no smaller than half the ground sample distance."""
        if not math.isfinite(gsd_m) or gsd_m <= 2.0 * self.resolution_m:
            return 0
        return min(len(self.levels) - 1, int(math.floor(math.log2(gsd_m / self.resolution_m))))

    def temperature(self, byte_image: np.ndarray) -> np.ndarray:
        """Temperature channel (uint8) -> Kelvin (float32)."""
        k = self.thermal_span_K / 255.0
        out = byte_image.astype(np.float32)
        out *= k
        out += self.ambient_K - 128.0 * k
        return out


@dataclass
class GroundLayer:
    """The ground as seen by the camera: ``rgbt`` (H×W×4 uint8) and the ``sky`` mask (or None)."""

    rgbt: np.ndarray
    sky: np.ndarray | None


def _window(
    texture: GroundTexture, level: int, n_min: float, e_min: float, box: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Texture level (averaged over ``box``×``box`` texels, :meth:`GroundTexture.boxed`) and the affine map ``A``
    from its (col, row, 1) to world (n, e, 1). A texel of the averaged level is centred on the middle of the
    ``box``×``box`` texels it averages, ``(box − 1)/2`` texels of the level from its first one."""
    tex = texture.levels[level]
    if box > 1 and tex.shape[0] % box == 0:
        tex = texture.boxed(level, box)
    else:
        box = 1
    res = texture.resolution_m * 2**level
    period = texture.period_m
    n0 = texture.origin_ne[0] + math.floor((n_min - texture.origin_ne[0]) / period) * period
    e0 = texture.origin_ne[1] + math.floor((e_min - texture.origin_ne[1]) / period) * period
    if box > 1:
        n0, e0, res = n0 + 0.5 * (box - 1) * res, e0 + 0.5 * (box - 1) * res, box * res
    A = np.array([[0.0, res, n0], [res, 0.0, e0], [0.0, 0.0, 1.0]])
    return tex, A


def texel_box(texture: GroundTexture, level: int, gsd_m: float, downsample: int) -> int:
    """Texels of mip ``level`` to average (per axis) for an image ``downsample`` times coarser than one of ground
    sample distance ``gsd_m``: the ``downsample·gsd / texel`` texels one of its pixels covers, rounded, at least
    1 and at most ``downsample`` (the texel of the level that suits ``gsd`` is at least ``gsd/2``)."""
    if downsample <= 1 or not math.isfinite(gsd_m):
        return 1
    texel = texture.resolution_m * 2**level
    return int(min(downsample, max(1, round(downsample * gsd_m / texel))))


class FlatGround:
    """How one frame sees flat ground at height ``h0``: the mip level, the homography from its texels to the
    frame's pixels and the horizon, worked out once; :meth:`layer` warps the frame, or any part of it."""

    def __init__(self, texture: GroundTexture, P: np.ndarray, width: int, height: int, h0: float):
        G = np.column_stack([P[:, 0], P[:, 1], -h0 * P[:, 2] + P[:, 3]])
        Ginv = np.linalg.inv(G)
        x1, y1 = width - 0.5, height - 0.5
        corners = np.array([[-0.5, -0.5, 1], [x1, -0.5, 1], [x1, y1, 1], [-0.5, y1, 1]])
        w = corners @ Ginv[2]
        centre = np.array([(width - 1) / 2, (height - 1) / 2, 1.0])
        pts = np.stack([centre, centre + [1, 0, 0], centre + [0, 1, 0]]) @ Ginv.T
        if np.all(pts[:, 2] > 0):
            ne = pts[:, :2] / pts[:, 2:]
            d1, d2 = ne[1] - ne[0], ne[2] - ne[0]
            gsd = math.sqrt(abs(d1[0] * d2[1] - d1[1] * d2[0]))
        else:
            gsd = float("inf")
        self.gsd, self.level = gsd, texture.level_for(gsd)
        self.horizon = None  # Ginv[2] when the horizon crosses the frame: pixel p is sky where Ginv[2]·p ≤ 0
        self.origin = (0.0, 0.0)  # where the texture window starts (n, e)
        if np.all(w > 1e-12):
            ground = corners @ Ginv.T
            ne = ground[:, :2] / ground[:, 2:]
            (n_min, e_min), (n_max, e_max) = ne.min(axis=0), ne.max(axis=0)
            self.origin = (n_min, e_min)
            tex, A = _window(texture, self.level, n_min, e_min)
            span = 2 * texture.period_m
            inside = n_max - A[0, 2] < span - 2 * A[0, 1] and e_max - A[1, 2] < span - 2 * A[0, 1]
            self.border = cv2.BORDER_REPLICATE if inside else cv2.BORDER_WRAP
        else:
            tex, A = _window(texture, self.level, 0.0, 0.0)
            self.border = cv2.BORDER_WRAP
            self.horizon = Ginv[2]
        self.texture, self.G, self.M, self.size = texture, G, G @ A, (width, height)
        self._tex = tex

    def layer(
        self, A: np.ndarray | None = None, size: tuple[int, int] | None = None, downsample: int = 1
    ) -> GroundLayer:
        """The ground of the frame (``A = None``), or of the ``size = (w, h)`` image whose pixel ``p'`` is frame
        pixel ``p`` at ``p' ~ A·p`` (``A`` a 3×3 pixel map: a window, a lower resolution). An image whose pixels
        stand for ``downsample``×``downsample`` frame pixels each (their mean, as ``cv2.INTER_AREA`` makes it)
        samples the frame's mip level averaged over the texels those pixels cover
        (:func:`texel_box`)."""
        width, height = self.size if size is None else size
        tex, M, horizon = self._tex, self.M, self.horizon
        box = texel_box(self.texture, self.level, self.gsd, downsample)
        if box > 1:
            tex, window = _window(self.texture, self.level, *self.origin, box)
            M = self.G @ window
        if A is not None:
            M = A @ M
            horizon = None if horizon is None else horizon @ np.linalg.inv(A)
        sky = None
        if horizon is not None:
            u = np.arange(width, dtype=np.float32)
            v = np.arange(height, dtype=np.float32)[:, None]
            sky = (horizon[0] * u + horizon[1] * v + horizon[2]) <= 1e-12
        rgbt = cv2.warpPerspective(tex, M, (width, height), flags=cv2.INTER_LINEAR, borderMode=self.border)
        return GroundLayer(rgbt, sky)


def _terrain(
    texture: GroundTexture,
    P: np.ndarray,
    width: int,
    height: int,
    height_fn: Callable,
    step: int = 8,
    downsample: int = 1,
) -> GroundLayer:
    M = P[:, :3]
    Minv = np.linalg.inv(M)
    C = -Minv @ P[:, 3]
    wc, hc = math.ceil(width / step) + 1, math.ceil(height / step) + 1
    # Coarse samples placed where cv2.resize (wc, hc) -> (width, height) expects them.
    u = (np.arange(wc) + 0.5) * width / wc - 0.5
    v = (np.arange(hc) + 0.5) * height / hc - 0.5
    uu, vv = np.meshgrid(u, v)
    rays = np.stack([uu, vv, np.ones_like(uu)], -1) @ Minv.T  # world directions (unnormalised)
    dz = rays[..., 2]
    ok = dz > 1e-9
    dz_safe = np.where(ok, dz, 1.0)
    h = np.full(uu.shape, float(np.asarray(height_fn(C[0], C[1]))))
    lam = (-h - C[2]) / dz_safe
    for _ in range(12):  # damped fixed point on λ: C_z + λ d_z = −h(C_ne + λ d_ne)
        n = C[0] + lam * rays[..., 0]
        e = C[1] + lam * rays[..., 1]
        h = np.asarray(height_fn(n, e), float)
        lam = 0.5 * lam + 0.5 * (-h - C[2]) / dz_safe
    ok &= lam > 0
    n = C[0] + lam * rays[..., 0]
    e = C[1] + lam * rays[..., 1]
    ci, cj = hc // 2, wc // 2
    gsd = math.hypot(n[ci, cj + 1] - n[ci, cj], e[ci, cj + 1] - e[ci, cj]) * wc / width
    level = texture.level_for(gsd / downsample)
    box = texel_box(texture, level, gsd / downsample, downsample)
    if ok.any():
        tex, A = _window(texture, level, float(n[ok].min()), float(e[ok].min()), box)
    else:
        tex, A = _window(texture, level, 0.0, 0.0, box)
    res = A[0, 1]
    period_px = texture.period_m / res
    mx = np.where(ok, (e - A[1, 2]) / res, 0.0).astype(np.float32)
    my = np.where(ok, (n - A[0, 2]) / res, 0.0).astype(np.float32)
    map_x = cv2.resize(mx, (width, height), interpolation=cv2.INTER_LINEAR)
    map_y = cv2.resize(my, (width, height), interpolation=cv2.INTER_LINEAR)
    if max(float(mx.max()), float(my.max())) > 2 * period_px - 2:
        # Larger than the 2×2-tiled window: wrap at full resolution (the texture is periodic).
        map_x, map_y = np.mod(map_x, period_px), np.mod(map_y, period_px)
    rgbt = cv2.remap(tex, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    sky = None
    if not ok.all():
        sky = cv2.resize((~ok).astype(np.uint8), (width, height), interpolation=cv2.INTER_NEAREST) > 0
    return GroundLayer(rgbt, sky)


class TerrainGround:
    """How one frame sees a terrain ``h(n, e)``: :meth:`layer` casts the coarse grid of rays of its image (a
    window's grid nodes are its own, so its texture agrees with the whole frame's to a fraction of a texel)."""

    def __init__(self, texture: GroundTexture, P: np.ndarray, width: int, height: int, height_fn: Callable):
        self.texture, self.P, self.size, self.height_fn = texture, P, (width, height), height_fn

    def layer(
        self, A: np.ndarray | None = None, size: tuple[int, int] | None = None, downsample: int = 1
    ) -> GroundLayer:
        """As :meth:`FlatGround.layer` (the ground sample distance is the image's, ÷ ``downsample``)."""
        P = self.P if A is None else A @ self.P
        return _terrain(self.texture, P, *(self.size if size is None else size), self.height_fn, downsample=downsample)


def ground_view(
    texture: GroundTexture,
    P: np.ndarray,
    width: int,
    height: int,
    ground_height: float = 0.0,
    terrain: Callable | object | None = None,
) -> FlatGround | TerrainGround:
    """How the ``width``×``height`` frame of the normalised projection ``P`` (depth = ``P[2]·[X; 1]`` > 0) sees
    ``texture`` on ``terrain``: ``None`` (flat ground at ``ground_height`` m above the NED origin), an object with
    ``height(n, e)`` (e.g. :class:`perception.terrain.HillsTerrain`) or a callable ``h(n, e)``."""
    if terrain is None:
        return FlatGround(texture, P, width, height, ground_height)
    fn = terrain.height if hasattr(terrain, "height") else terrain
    return TerrainGround(texture, P, width, height, fn)
