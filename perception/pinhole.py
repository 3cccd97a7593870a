"""A plain pinhole view ``P = K [R | t]`` for the synthetic camera (no distortion).

The renderer needs the linear projection itself (the ground is drawn through the plane-to-image
homography), so it accepts whatever describes one and turns it into a :class:`PinholeView`:

* a :class:`PinholeView`; a 3×4 matrix ``P`` (any scale or sign); a tuple ``(K, R, t)`` with
  ``R = R_cam_from_world`` and ``X_cam = R X_world + t``;
* a pair ``(pose, intrinsics)`` duck-typed on ``pose.R_world_from_cam``, ``pose.centre`` and
  ``intrinsics.fx, fy, cx, cy`` (distortion must be zero);
* a callable ``project(points_world (N, 3)) -> (pixels (N, 2), depth (N,))`` of a pinhole camera,
  or one returning pixels only with NaN rows behind the camera: ``P`` is recovered by the DLT
  (Hartley-normalised) from points around ``anchors`` and checked by reprojection; a non-pinhole
  callable is refused.

Frames: world NED, camera OpenCV (x right, y down, z along the optical axis), pixel centres at
integer coordinates (DESIGN.md §3).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["PinholeView", "as_view"]


@dataclass(frozen=True)
class PinholeView:
    """``X_cam = R X_world + t``, ``pixel ~ K X_cam``; ``depth = (X_cam)_z``."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray

    def __post_init__(self) -> None:
        K = np.array(self.K, float)
        R = np.array(self.R, float)
        t = np.array(self.t, float).reshape(-1)
        if K.shape != (3, 3) or R.shape != (3, 3) or t.shape != (3,):
            raise ValueError("need K (3, 3), R (3, 3) and t (3,)")
        if not (np.all(np.isfinite(K)) and np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise ValueError("camera parameters must be finite")
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("R must be a rotation matrix")
        if K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] == 0 or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError("K must be upper triangular with positive focal lengths")
        K = K / K[2, 2]
        for name, value in (("K", K), ("R", R), ("t", t)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def P(self) -> np.ndarray:
        """3×4 projection, normalised so that ``P[2] · [X; 1]`` is the depth."""
        return self.K @ np.column_stack([self.R, self.t])

    @property
    def center(self) -> np.ndarray:
        return -self.R.T @ self.t

    @property
    def focal(self) -> float:
        return math.sqrt(self.K[0, 0] * self.K[1, 1])

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) -> pixels (N, 2) and depths (N,); pixels are NaN at depth ≤ 0."""
        X = np.asarray(points, float).reshape(-1, 3)
        cam = X @ self.R.T + self.t
        depth = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uvw = cam @ self.K.T
            uv = uvw[:, :2] / uvw[:, 2:]
        uv[depth <= 0] = np.nan
        return uv, depth

    @classmethod
    def from_matrix(cls, P) -> PinholeView:
        P = np.array(P, float)
        if P.shape != (3, 4) or not np.all(np.isfinite(P)):
            raise ValueError("projection matrix must be a finite 3×4 array")
        if np.linalg.det(P[:, :3]) < 0:
            P = -P
        K, R, C, *_ = cv2.decomposeProjectionMatrix(P)
        D = np.diag(np.sign(np.diag(K)))
        K, R = K @ D, D @ R
        C = C[:3, 0] / C[3, 0]
        return cls(K / K[2, 2], R, -R @ C)

    @classmethod
    def look_at(cls, eye, target, width: int, height: int, hfov: float, up=None) -> PinholeView:
        """Camera at ``eye`` (NED) looking at ``target``, horizontal field of view ``hfov`` (rad).

        ``up`` is the world direction to show at the top of the image: north when looking
        (nearly) straight down, world up (−z) otherwise."""
        eye, target = np.asarray(eye, float), np.asarray(target, float)
        z = target - eye
        z /= np.linalg.norm(z)
        if up is None:
            up = np.array([1.0, 0, 0]) if abs(z[2]) > 0.99 else np.array([0, 0, -1.0])
        up = np.asarray(up, float)
        y = -(up - (up @ z) * z)
        if np.linalg.norm(y) < 1e-9:
            raise ValueError("up direction is parallel to the viewing direction")
        y /= np.linalg.norm(y)
        x = np.cross(y, z)
        R = np.stack([x, y, z])
        f = (width / 2.0) / math.tan(hfov / 2.0)
        K = np.array([[f, 0, (width - 1) / 2.0], [0, f, (height - 1) / 2.0], [0, 0, 1]])
        return cls(K, R, -R @ eye)

    @classmethod
    def from_callable(cls, project: Callable, anchors: Sequence = ((0.0, 0.0, 0.0),), seed: int = 0) -> PinholeView:
        """Recover ``P`` from a pinhole ``project(points) -> (pixels, depth)`` (or ``-> pixels``) by
        the DLT. Points are drawn at 1 m to 10 km around ``anchors`` (e.g. the targets)."""
        rng = np.random.default_rng(seed)
        centres = np.asarray(anchors, float).reshape(-1, 3)
        pts = np.concatenate([c + rng.uniform(-s, s, (48, 3)) for c in centres for s in (1, 10, 100, 1000, 1e4)])
        result = project(pts)
        if isinstance(result, tuple) and len(result) == 2:
            uv, depth = np.asarray(result[0], float).reshape(-1, 2), np.asarray(result[1], float).reshape(-1)
        else:  # pixels only, NaN behind the camera (as perception.projection.world_to_pixel does)
            uv = np.asarray(result, float).reshape(-1, 2)
            depth = np.ones(len(uv))
        ok = np.all(np.isfinite(uv), axis=1) & np.isfinite(depth) & (depth > 0)
        ok &= np.all(np.abs(np.nan_to_num(uv)) < 1e5, axis=1)  # grazing points only hurt the conditioning
        X, x = pts[ok], uv[ok]
        if len(X) < 12:
            raise ValueError("the projection callable gave too few points in front of the camera")
        # Hartley normalisation of both point sets.
        mx, sx = x.mean(0), np.sqrt(2) / np.mean(np.linalg.norm(x - x.mean(0), axis=1))
        mX, sX = X.mean(0), np.sqrt(3) / np.mean(np.linalg.norm(X - X.mean(0), axis=1))
        T = np.array([[sx, 0, -sx * mx[0]], [0, sx, -sx * mx[1]], [0, 0, 1]])
        U = np.diag([sX, sX, sX, 1.0])
        U[:3, 3] = -sX * mX
        xn = (x - mx) * sx
        Xn = np.column_stack([(X - mX) * sX, np.ones(len(X))])
        A = np.zeros((2 * len(X), 12))
        A[0::2, 0:4], A[0::2, 8:12] = Xn, -xn[:, :1] * Xn
        A[1::2, 4:8], A[1::2, 8:12] = Xn, -xn[:, 1:] * Xn
        Pn = np.linalg.svd(A)[2][-1].reshape(3, 4)
        P = np.linalg.inv(T) @ Pn @ U  # any scale and sign: from_matrix normalises both
        view = cls.from_matrix(P)
        err = np.nanmax(np.linalg.norm(view.project(X)[0] - x, axis=1))
        if not err < 1e-2 + 1e-6 * float(np.abs(x).max()):
            raise ValueError(f"the projection callable is not a pinhole camera (DLT residual {err:.3g} px)")
        return view


def as_view(camera, anchors: Sequence = ((0.0, 0.0, 0.0),)) -> PinholeView:
    """Any supported camera description (see the module docstring) -> :class:`PinholeView`."""
    if isinstance(camera, PinholeView):
        return camera
    if isinstance(camera, np.ndarray) and camera.shape == (3, 4):
        return PinholeView.from_matrix(camera)
    if isinstance(camera, tuple | list):
        if len(camera) == 3:
            return PinholeView(*camera)
        if len(camera) == 2 and hasattr(camera[0], "R_world_from_cam"):
            pose, intr = camera
            if any(abs(float(k)) > 0 for k in getattr(intr, "dist", ()) or ()):
                raise ValueError("the synthetic camera renders without lens distortion")
            K = np.array([[intr.fx, getattr(intr, "skew", 0.0), intr.cx], [0, intr.fy, intr.cy], [0, 0, 1.0]])
            R = np.asarray(pose.R_world_from_cam, float).T
            return PinholeView(K, R, -R @ np.asarray(pose.centre, float))
    if all(hasattr(camera, a) for a in ("K", "R", "t")):
        return PinholeView(camera.K, camera.R, camera.t)
    if callable(camera):
        return PinholeView.from_callable(camera, anchors)
    raise TypeError(f"cannot use {type(camera).__name__} as a camera: see perception.pinhole")
