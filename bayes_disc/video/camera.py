"""Pinhole camera with OpenCV lens distortion.

Conventions (OpenCV): a world point X (m, world frame of docs/conventions.md) has camera coordinates
``Xc = R X + t`` (camera x right, y down, z forward along the optical axis); the ideal normalised image
point is ``x = (Xc/Zc, Yc/Zc)``; lens distortion maps it to ``x_d`` with the OpenCV model

    r² = x² + y²,  a = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)
    x_d = x a + 2 p1 x y + p2 (r² + 2 x²)
    y_d = y a + p1 (r² + 2 y²) + 2 p2 x y

and the pixel is ``(u, v) = (fx x_d + s y_d + cx, fy y_d + cy)``. Pixel coordinates have the origin at
the top-left corner with pixel centres at integers (pixel (0, 0) covers [-0.5, 0.5]²), as in OpenCV.
Distortion coefficients are given in OpenCV order ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])``.

Projection is implemented in numpy (vectorised, with the analytic Jacobian that triangulation needs)
and tested against ``cv2.projectPoints``; undistortion inverts the model by Newton's method (to
~1e-13 px; ``cv2.undistortPoints`` agrees to ~1e-4 px).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_DIST_LENGTHS = (0, 4, 5, 8)


def _dist8(dist) -> np.ndarray:
    d = np.zeros(8)
    dist = np.asarray(dist if dist is not None else [], float).ravel()
    if dist.size not in _DIST_LENGTHS:
        raise ValueError(f"distortion: {dist.size} coefficients; expected 0, 4, 5 or 8 "
                         "(k1, k2, p1, p2[, k3[, k4, k5, k6]]); thin-prism and tilt terms are not supported")
    d[:dist.size] = dist
    return d


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated camera.

    name; K (3, 3) intrinsic matrix [px] (fx, skew s, cx; fy, cy); R (3, 3) world→camera rotation;
    t (3,) camera-frame position of the world origin [m]; dist: OpenCV distortion coefficients (0, 4, 5
    or 8 values); image_size: (width, height) [px].
    """

    name: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(0))
    image_size: tuple = (0, 0)

    def __post_init__(self):
        K = np.asarray(self.K, float).reshape(3, 3)
        R = np.asarray(self.R, float).reshape(3, 3)
        t = np.asarray(self.t, float).reshape(3)
        if not (np.all(np.isfinite(K)) and np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise ValueError(f"camera {self.name!r}: K, R and t must be finite")
        if abs(K[2, 2]) < 1e-12:
            raise ValueError(f"camera {self.name!r}: K[2,2] must not be zero")
        K = K / K[2, 2]
        if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[1, 0]) > 1e-9 or abs(K[2, 0]) > 1e-9 or abs(K[2, 1]) > 1e-9:
            raise ValueError(f"camera {self.name!r}: K must be upper triangular with positive fx, fy")
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
            raise ValueError(f"camera {self.name!r}: R must be a rotation matrix (orthonormal, det +1)")
        dist = np.asarray(self.dist if self.dist is not None else [], float).ravel()
        _dist8(dist)
        size = tuple(int(s) for s in self.image_size)
        if len(size) != 2 or min(size) < 0:
            raise ValueError(f"camera {self.name!r}: image_size must be (width, height)")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "image_size", size)
        object.__setattr__(self, "_d8", _dist8(dist))

    # -- geometry ----------------------------------------------------------------------------------------
    @property
    def center(self) -> np.ndarray:
        """Projection centre in world coordinates [m]: C = −Rᵀ t."""
        return -self.R.T @ self.t

    @property
    def P(self) -> np.ndarray:
        """Projection matrix K [R | t] (3, 4) of the undistorted pinhole model."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self._d8 != 0))

    @property
    def width(self) -> int:
        return self.image_size[0]

    @property
    def height(self) -> int:
        return self.image_size[1]

    def to_camera(self, X) -> np.ndarray:
        """Camera-frame coordinates Xc = R X + t of world points X (..., 3)."""
        return np.asarray(X, float) @ self.R.T + self.t

    def depth(self, X) -> np.ndarray:
        """Depth Zc along the optical axis [m] of world points X (..., 3)."""
        return self.to_camera(X)[..., 2]

    # -- distortion ----------------------------------------------------------------------------------------
    def _radial(self, r2):
        k1, k2, p1, p2, k3, k4, k5, k6 = self._d8
        num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2)
        dden = k4 + r2 * (2 * k5 + 3 * k6 * r2)
        return num / den, (dnum * den - num * dden) / (den * den)

    def distort(self, xn) -> np.ndarray:
        """Ideal normalised coordinates (..., 2) → distorted normalised coordinates (..., 2)."""
        xn = np.asarray(xn, float)
        x, y = xn[..., 0], xn[..., 1]
        p1, p2 = self._d8[2], self._d8[3]
        r2 = x * x + y * y
        a, _ = self._radial(r2)
        xd = x * a + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * a + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def _distort_jacobian(self, xn):
        """Distorted coordinates and their Jacobian ∂x_d/∂x (..., 2, 2)."""
        x, y = xn[..., 0], xn[..., 1]
        p1, p2 = self._d8[2], self._d8[3]
        r2 = x * x + y * y
        a, da = self._radial(r2)
        xd = x * a + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * a + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        J = np.empty(xn.shape[:-1] + (2, 2))
        J[..., 0, 0] = a + 2 * x * x * da + 2 * p1 * y + 6 * p2 * x
        J[..., 0, 1] = 2 * x * y * da + 2 * p1 * x + 2 * p2 * y
        J[..., 1, 0] = 2 * x * y * da + 2 * p1 * x + 2 * p2 * y
        J[..., 1, 1] = a + 2 * y * y * da + 6 * p1 * y + 2 * p2 * x
        return np.stack([xd, yd], axis=-1), J

    def undistort_normalized(self, xd, iterations: int = 30, tol: float = 1e-14) -> np.ndarray:
        """Distorted normalised coordinates (..., 2) → ideal ones, by Newton's method on :meth:`distort`."""
        xd = np.asarray(xd, float)
        if not self.has_distortion:
            return xd.copy()
        x = xd.copy()
        for _ in range(iterations):
            f, J = self._distort_jacobian(x)
            r = f - xd
            det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
            dx = (J[..., 1, 1] * r[..., 0] - J[..., 0, 1] * r[..., 1]) / det
            dy = (-J[..., 1, 0] * r[..., 0] + J[..., 0, 0] * r[..., 1]) / det
            x[..., 0] -= dx
            x[..., 1] -= dy
            if np.nanmax(np.abs(np.concatenate([np.ravel(dx), np.ravel(dy), [0.0]]))) < tol:
                break
        return x

    # -- pixels ------------------------------------------------------------------------------------------
    def normalized_to_pixel(self, xd) -> np.ndarray:
        """Distorted normalised coordinates (..., 2) → pixels (..., 2)."""
        xd = np.asarray(xd, float)
        K = self.K
        u = K[0, 0] * xd[..., 0] + K[0, 1] * xd[..., 1] + K[0, 2]
        v = K[1, 1] * xd[..., 1] + K[1, 2]
        return np.stack([u, v], axis=-1)

    def pixel_to_distorted(self, uv) -> np.ndarray:
        """Pixels (..., 2) → distorted normalised coordinates (..., 2)."""
        uv = np.asarray(uv, float)
        K = self.K
        y = (uv[..., 1] - K[1, 2]) / K[1, 1]
        x = (uv[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=-1)

    def undistort_pixels(self, uv) -> np.ndarray:
        """Pixels (..., 2) → ideal (undistorted) normalised coordinates (..., 2)."""
        return self.undistort_normalized(self.pixel_to_distorted(uv))

    def project(self, X) -> np.ndarray:
        """World points X (..., 3) [m] → pixels (..., 2), distortion applied (NaN behind the camera)."""
        Xc = self.to_camera(X)
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = Xc[..., :2] / z[..., None]
        uv = self.normalized_to_pixel(self.distort(xn))
        uv[z <= 0] = np.nan
        return uv

    def project_jacobian(self, X):
        """Pixels (..., 2) of world points X (..., 3) and the Jacobian ∂(u, v)/∂X (..., 2, 3) [px/m]."""
        X = np.asarray(X, float)
        Xc = self.to_camera(X)
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = Xc[..., :2] / z[..., None]
            xd, Jd = self._distort_jacobian(xn)
            dxn = np.zeros(X.shape[:-1] + (2, 3))
            dxn[..., 0, 0] = 1 / z
            dxn[..., 1, 1] = 1 / z
            dxn[..., 0, 2] = -xn[..., 0] / z
            dxn[..., 1, 2] = -xn[..., 1] / z
        Kp = self.K[:2, :2]
        J = Kp @ Jd @ dxn @ self.R
        uv = self.normalized_to_pixel(xd)
        uv[z <= 0] = np.nan
        return uv, J

    def in_image(self, uv, margin: float = 0.0) -> np.ndarray:
        """True where pixels (..., 2) lie inside the image, at least ``margin`` px from its border."""
        uv = np.asarray(uv, float)
        w, h = self.image_size
        return ((uv[..., 0] >= -0.5 + margin) & (uv[..., 0] <= w - 0.5 - margin)
                & (uv[..., 1] >= -0.5 + margin) & (uv[..., 1] <= h - 0.5 - margin))

    # -- DLT ----------------------------------------------------------------------------------------------
    def dlt_coefficients(self) -> np.ndarray:
        """The 11 DLT coefficients L1..L11 of the pinhole part, u = (L1 X + L2 Y + L3 Z + L4)/(L9 X + L10 Y
        + L11 Z + 1), v = (L5 X + ... + L8)/(...) in this camera's pixel convention (distortion not
        included)."""
        P = self.P
        return (P / P[2, 3]).ravel()[:11]

    def replace(self, **changes) -> "Camera":
        kw = dict(name=self.name, K=self.K, R=self.R, t=self.t, dist=self.dist, image_size=self.image_size)
        kw.update(changes)
        return Camera(**kw)


def look_at(name: str, position, target, focal_px: float, image_size, up=(0.0, 0.0, 1.0),
            principal_point=None, dist=(), skew: float = 0.0, aspect: float = 1.0) -> Camera:
    """A camera at ``position`` [m] looking at ``target`` [m] with image 'up' close to world ``up``.

    focal_px: fx [px]; fy = aspect·fx; principal_point defaults to the image centre ((w−1)/2, (h−1)/2).
    """
    C = np.asarray(position, float)
    z = np.asarray(target, float) - C
    if np.linalg.norm(z) == 0:
        raise ValueError(f"camera {name!r}: position and target coincide")
    z /= np.linalg.norm(z)
    up = np.asarray(up, float)
    x = np.cross(z, up)  # camera x (right) = forward × up
    if np.linalg.norm(x) < 1e-9:
        raise ValueError(f"camera {name!r}: viewing direction is parallel to 'up'")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)  # camera y (down)
    R = np.stack([x, y, z])
    w, h = int(image_size[0]), int(image_size[1])
    cx, cy = ((w - 1) / 2, (h - 1) / 2) if principal_point is None else principal_point
    K = np.array([[focal_px, skew, cx], [0, focal_px * aspect, cy], [0, 0, 1.0]])
    return Camera(name, K, R, -R @ C, np.asarray(dist, float), (w, h))
