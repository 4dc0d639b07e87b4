"""Pinhole camera models in OpenCV convention (x right, y down, z forward; pixel centres at
integer coordinates), posed in the arm base frame, and the stereo pair that triangulates.

A :class:`CameraModel` is what calibration produces and what every detector uses. The
true model of a simulated camera (:func:`serpar.calibration.camera_truth.true_camera`) lives
above vision: it exists only to score calibration and vision against.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from serpar.vision.errors import ImageError


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics (K, distortion) at `size` and the camera pose in the arm base frame."""

    name: str
    size: tuple[int, int]
    """(width, height) in pixels the intrinsics refer to."""
    K: NDArray[np.float64]
    dist: NDArray[np.float64]
    """OpenCV distortion coefficients (k1, k2, p1, p2, k3)."""
    rot: NDArray[np.float64] = field(default_factory=lambda: np.eye(3))
    """Camera axes (columns) in the base frame."""
    pos: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    """Optical centre in the base frame [m]."""

    @property
    def rvec_tvec(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """OpenCV extrinsics (base -> camera)."""
        r_cw = self.rot.T
        return cv2.Rodrigues(r_cw)[0].ravel(), -r_cw @ self.pos

    def to_camera(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Base-frame points (N, 3) in camera coordinates."""
        return (np.atleast_2d(points) - self.pos) @ self.rot

    def project(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Pixel coordinates (N, 2) of base-frame points (N, 3)."""
        rvec, tvec = self.rvec_tvec
        uv, _ = cv2.projectPoints(np.atleast_2d(points).astype(np.float64), rvec, tvec, self.K, self.dist)
        return uv.reshape(-1, 2)

    def undistort(self, uv: NDArray[np.float64]) -> NDArray[np.float64]:
        """Normalised image coordinates (N, 2) (z = 1 in the camera frame) of pixels."""
        pts = np.atleast_2d(uv).astype(np.float64).reshape(-1, 1, 2)
        return cv2.undistortPoints(pts, self.K, self.dist).reshape(-1, 2)

    def rays(self, uv: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unit viewing rays (N, 3) in the base frame through pixels `uv`."""
        n = self.undistort(uv)
        d = np.c_[n, np.ones(len(n))] @ self.rot.T
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def metres_per_pixel(self, distance: float) -> float:
        return distance / float(self.K[0, 0])

    def scaled(self, size: tuple[int, int]) -> CameraModel:
        """The same camera read out at another size of the same aspect (binning / resize)."""
        s = size[0] / self.size[0]
        if abs(size[1] / self.size[1] - s) > 1e-3:
            raise ImageError(f"size {size[0]}x{size[1]} has another aspect than {self.size[0]}x{self.size[1]}")
        K = self.K.copy()
        K[0, 0] *= s
        K[1, 1] *= s
        K[0, 2] = (K[0, 2] + 0.5) * s - 0.5
        K[1, 2] = (K[1, 2] + 0.5) * s - 0.5
        return replace(self, size=size, K=K)

    def as_dict(self) -> dict[str, object]:
        return {"name": self.name, "size": list(self.size), "K": self.K.tolist(), "dist": self.dist.tolist(),
                "rot": self.rot.tolist(), "pos": self.pos.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> CameraModel:
        try:
            return cls(str(d["name"]), (int(d["size"][0]), int(d["size"][1])), np.array(d["K"], float),
                       np.array(d["dist"], float), np.array(d["rot"], float), np.array(d["pos"], float))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise ImageError(f"camera model: missing or malformed field ({exc}); "
                             "needs name, size, K, dist, rot, pos") from None

    def check_image(self, image: np.ndarray) -> np.ndarray:
        """`image` as it is if it is an 8-bit RGB or grey image of this camera's size; else ImageError."""
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
            kind = image.dtype if isinstance(image, np.ndarray) else type(image).__name__
            raise ImageError(f"camera {self.name}: image must be a uint8 array, got {kind}")
        if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
            raise ImageError(f"camera {self.name}: image must be HxW or HxWx3, got shape {image.shape}")
        if (image.shape[1], image.shape[0]) != self.size:
            raise ImageError(f"camera {self.name}: image is {image.shape[1]}x{image.shape[0]}, "
                             f"the camera model is {self.size[0]}x{self.size[1]}")
        return image


@dataclass(frozen=True)
class StereoPair:
    """Two calibrated cameras that see the same scene."""

    left: CameraModel
    right: CameraModel

    @property
    def baseline(self) -> float:
        return float(np.linalg.norm(self.right.pos - self.left.pos))

    def scaled(self, size: tuple[int, int]) -> StereoPair:
        return StereoPair(self.left.scaled(size), self.right.scaled(size))

    def triangulate(self, uv_left: NDArray[np.float64], uv_right: NDArray[np.float64]) -> NDArray[np.float64]:
        """Base-frame points (N, 3) from matched pixels: midpoint of the closest approach of the rays."""
        o1, o2 = self.left.pos, self.right.pos
        d1, d2 = self.left.rays(uv_left), self.right.rays(uv_right)
        w0 = o1 - o2
        b = np.sum(d1 * d2, axis=1)
        d, e = d1 @ w0, d2 @ w0
        denom = 1.0 - b**2
        s = (b * e - d) / denom
        t = (e - b * d) / denom
        return 0.5 * ((o1 + s[:, None] * d1) + (o2 + t[:, None] * d2))

    def reprojection_error(self, points: NDArray[np.float64], uv_left: NDArray[np.float64],
                           uv_right: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per point, the larger of the two image distances [px] between `points` and the pixels."""
        el = np.linalg.norm(self.left.project(points) - uv_left, axis=1)
        er = np.linalg.norm(self.right.project(points) - uv_right, axis=1)
        return np.maximum(el, er)
