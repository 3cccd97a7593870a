"""Pin-hole camera intrinsics with optional OpenCV lens distortion.

Camera frame (DESIGN.md §3): OpenCV, x right, y down, z along the optical axis. Pixel coordinates
``(u, v)`` have u to the right and v down, and the centre of the top-left pixel is ``(0, 0)``, so the
image spans ``[-0.5, width - 0.5] x [-0.5, height - 0.5]`` (OpenCV's convention).

Projection (Merino (3.57) ``s m = A (R  -t) p`` with the intrinsic matrix
``A = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``, and OpenCV's distortion model, as ``cv2.projectPoints``):

    x' = X/Z,  y' = Y/Z,  r² = x'² + y'²,  k(r²) = 1 + k1 r² + k2 r⁴ + k3 r⁶
    x" = x' k + 2 p1 x'y' + p2 (r² + 2x'²),   y" = y' k + p1 (r² + 2y'²) + 2 p2 x'y'
    u = fx x" + cx,  v = fy y" + cy

The inverse (``ray``) undoes the distortion by a damped Newton iteration on the 2x2 system, to
machine precision (``cv2.undistortPoints`` stops after a handful of fixed-point steps, about 1e-6
pixel; the two agree to that level, tested). Ross et al. use focal length and principal point only
(spec 002 §2.2); that is ``dist=()``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np

__all__ = ["Intrinsics", "MERINO_IR_CAMERA"]

#: Newton iterations allowed when undoing the distortion, and the residual in normalised image units
#: after which one last Newton step is taken (leaving a rounding-level error). Chosen here.
UNDISTORT_MAX_ITER = 50
UNDISTORT_TOL = 1e-14


def _finite_real(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        raise ValueError(f"intrinsics: {name} must be a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Intrinsics:
    """Focal lengths and principal point in pixels, image size in pixels, and OpenCV distortion
    coefficients ``()``, ``(k1, k2, p1, p2)`` or ``(k1, k2, p1, p2, k3)``.

    Invalid values raise :class:`ValueError`: non-positive or non-finite focal lengths, a principal
    point that is not finite, a non-positive image size, a wrong number of distortion coefficients,
    and a distortion that folds over inside the image (then the pixel -> ray map is not one-to-one)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: tuple[float, ...] = ()

    def __post_init__(self):
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, _finite_real(getattr(self, name), name))
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"intrinsics: focal lengths must be > 0, got fx={self.fx}, fy={self.fy}")
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Integral) or value <= 0:
                raise ValueError(f"intrinsics: {name} must be a positive integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        dist = tuple(_finite_real(k, "distortion coefficient") for k in np.asarray(self.dist, dtype=object).ravel())
        if len(dist) not in (0, 4, 5):
            raise ValueError(f"intrinsics: dist must have 0, 4 (k1, k2, p1, p2) or 5 (+k3) entries, got {len(dist)}")
        object.__setattr__(self, "_fold_r2", math.inf)
        if any(dist):
            object.__setattr__(self, "dist", dist + (0.0,) * (5 - len(dist)))
            k1, k2, _, _, k3 = self.dist
            # d(r k(r²))/dr = 1 + 3 k1 s + 5 k2 s² + 7 k3 s³ (s = r²): its first positive root is the fold.
            roots = np.roots([7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0])
            real = roots[(np.abs(roots.imag) <= 1e-12 * np.abs(roots)) & (roots.real > 0)].real
            object.__setattr__(self, "_fold_r2", float(real.min()) if real.size else math.inf)
            self._check_invertible()
        else:
            object.__setattr__(self, "dist", ())

    # ------------------------------------------------------------------------------ constructors
    @classmethod
    def from_matrix(cls, K, width: int, height: int, dist=()) -> Intrinsics:
        """From a 3x3 calibration matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (no skew)."""
        K = np.asarray(K, dtype=float)
        if K.shape != (3, 3):
            raise ValueError(f"intrinsics: the calibration matrix must be 3x3, got shape {K.shape}")
        if K[0, 1] != 0 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise ValueError("intrinsics: the calibration matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
        return cls(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), width, height, dist)

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float) -> Intrinsics:
        """Square pixels, principal point at the image centre ``((W-1)/2, (H-1)/2)`` and the
        horizontal field of view ``hfov_deg`` (degrees: a config-edge constructor) spanning the full
        image width: ``fx = fy = (W/2) / tan(hfov/2)``."""
        hfov_deg = _finite_real(hfov_deg, "hfov_deg")
        if not 0.0 < hfov_deg < 180.0:
            raise ValueError(f"intrinsics: hfov_deg must be in (0, 180), got {hfov_deg}")
        if isinstance(width, bool) or not isinstance(width, Integral) or width <= 0:
            raise ValueError(f"intrinsics: width must be a positive integer, got {width!r}")
        f = 0.5 * width / math.tan(0.5 * math.radians(hfov_deg))
        return cls(f, f, 0.5 * (width - 1), 0.5 * (height - 1), width, height)

    # --------------------------------------------------------------------------------- accessors
    @property
    def matrix(self) -> np.ndarray:
        """The calibration matrix ``A`` (Merino (3.57))."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def corners(self) -> np.ndarray:
        """Outer corners of the image, clockwise from top-left: (4, 2) pixels."""
        r, b = self.width - 0.5, self.height - 0.5
        return np.array([[-0.5, -0.5], [r, -0.5], [r, b], [-0.5, b]])

    def contains(self, pixels) -> np.ndarray | bool:
        """Whether pixels (..., 2) lie inside the image rectangle (NaN -> False)."""
        p = np.asarray(pixels, dtype=float)
        with np.errstate(invalid="ignore"):
            inside = (p[..., 0] >= -0.5) & (p[..., 0] <= self.width - 0.5)
            inside &= (p[..., 1] >= -0.5) & (p[..., 1] <= self.height - 0.5)
        return bool(inside) if inside.ndim == 0 else inside

    # ------------------------------------------------------------------------------- distortion
    def distort(self, xy) -> np.ndarray:
        """Normalised undistorted ``(x', y')`` -> normalised distorted ``(x", y")`` (..., 2)."""
        xy = np.asarray(xy, dtype=float)
        if not self.dist:
            return xy.copy()
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def _distort_jacobian(self, x, y):
        k1, k2, p1, p2, k3 = self.dist
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)  # d radial / d r²
        a = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        b = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        c = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        d = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        return a, b, c, d

    def undistort(self, xy_distorted) -> np.ndarray:
        """Inverse of :meth:`distort` by damped Newton iteration (start: the distorted point).
        Raises :class:`ValueError` if a point does not converge (far outside the calibrated field)."""
        target = np.asarray(xy_distorted, dtype=float)
        if not self.dist:
            return target.copy()
        shape = target.shape
        t = target.reshape(-1, 2)
        xy = t.copy()
        done = ~np.all(np.isfinite(t), axis=1)  # NaN in -> NaN out
        for _ in range(UNDISTORT_MAX_ITER):
            active = ~done
            if not np.any(active):
                break
            p = xy[active]
            r = self.distort(p) - t[active]
            err = np.hypot(r[:, 0], r[:, 1])
            conv = err <= UNDISTORT_TOL * (1.0 + np.hypot(t[active, 0], t[active, 1]))
            a, b, c, d = self._distort_jacobian(p[:, 0], p[:, 1])
            det = a * d - b * c
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.stack([(d * r[:, 0] - b * r[:, 1]) / det, (-c * r[:, 0] + a * r[:, 1]) / det], axis=1)
            # Damping: halve the step until the residual does not grow (at most 30 halvings).
            scale = np.ones(len(p))
            for _ in range(30):
                trial = p - scale[:, None] * step
                r_new = self.distort(trial) - t[active]
                worse = ~(np.hypot(r_new[:, 0], r_new[:, 1]) <= err) & ~conv
                if not np.any(worse):
                    break
                scale[worse] *= 0.5
            # A converged point still takes this last Newton step: quadratic convergence takes it from
            # the tolerance down to rounding level.
            new = np.where(np.isfinite(step), p - scale[:, None] * step, p)
            idx = np.flatnonzero(active)
            xy[idx] = new
            done[idx[conv]] = True
        with np.errstate(invalid="ignore"):
            beyond = np.sum(xy * xy, axis=1) >= self._fold_r2
        if not np.all(done) or np.any(beyond):
            raise ValueError("cannot undo the lens distortion for a pixel far outside the calibrated image")
        xy[~np.all(np.isfinite(t), axis=1)] = np.nan
        return xy.reshape(shape)

    def _check_invertible(self) -> None:
        """The distortion must be one-to-one over the image: the Jacobian determinant of
        :meth:`distort` stays positive on the undistorted region that maps onto the image, found by
        growing the radius along the corner and edge directions."""
        k1, k2, _, _, k3 = self.dist
        corner_xy = (self.corners - [self.cx, self.cy]) / [self.fx, self.fy]
        rho_image = 1.05 * float(np.max(np.hypot(corner_xy[:, 0], corner_xy[:, 1])))  # 5 % margin
        r = np.linspace(0.0, 4.0 * rho_image + 1.0, 4001)
        g = r * (1.0 + k1 * r**2 + k2 * r**4 + k3 * r**6)  # radial part along any direction
        dg = 1.0 + 3.0 * k1 * r**2 + 5.0 * k2 * r**4 + 7.0 * k3 * r**6
        reach = np.flatnonzero(g >= rho_image)
        folds = np.flatnonzero(dg <= 0.0)
        if reach.size == 0 or (folds.size and folds[0] <= reach[0]):
            raise ValueError("intrinsics: the radial distortion folds over inside the image (not invertible)")
        r_max = r[reach[0]]
        grid = np.linspace(-r_max, r_max, 61)
        X, Y = np.meshgrid(grid, grid)
        inside = X**2 + Y**2 <= r_max**2
        a, b, c, d = self._distort_jacobian(X[inside], Y[inside])
        if np.any(a * d - b * c <= 0.0):
            raise ValueError("intrinsics: the distortion folds over inside the image (not invertible)")

    # ------------------------------------------------------------------------------- projection
    def project(self, points_cam) -> np.ndarray:
        """Camera-frame points (..., 3) -> pixels (..., 2). Points with ``Z <= 0`` (on or behind
        the image plane through the optical centre) give NaN, and so do points beyond the radius
        where the radial distortion stops being monotonic (the polynomial would fold them back into
        the image: a point far outside the field of view must not appear inside it)."""
        P = np.asarray(points_cam, dtype=float)
        if P.shape[-1:] != (3,):
            raise ValueError(f"camera points must have shape (..., 3), got {P.shape}")
        z = P[..., 2]
        front = z > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = P[..., :2] / np.where(front, z, np.nan)[..., None]
            if self._fold_r2 < math.inf:
                xy[np.sum(xy * xy, axis=-1) >= self._fold_r2] = np.nan
        xy = self.distort(xy)
        return np.stack([self.fx * xy[..., 0] + self.cx, self.fy * xy[..., 1] + self.cy], axis=-1)

    def normalized(self, pixels) -> np.ndarray:
        """Pixels (..., 2) -> undistorted normalised coordinates ``(x', y')`` (..., 2)."""
        p = np.asarray(pixels, dtype=float)
        if p.shape[-1:] != (2,):
            raise ValueError(f"pixels must have shape (..., 2), got {p.shape}")
        xy = np.stack([(p[..., 0] - self.cx) / self.fx, (p[..., 1] - self.cy) / self.fy], axis=-1)
        return self.undistort(xy)

    def ray(self, pixels) -> np.ndarray:
        """Pixels (..., 2) -> unit viewing directions in the camera frame (..., 3), ``z > 0``."""
        xy = self.normalized(pixels)
        d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)


#: The infrared camera of Merino §3.7.1 (footnote 3). The thesis gives only A; the image size is not
#: stated — 240 x 320 is chosen here as the size whose centre is nearest the principal point.
MERINO_IR_CAMERA = Intrinsics(347.881, 345.876, 119.512, 161.781, 240, 320)
