"""Stereo calibration and registration to the arm base, from checkerboard views at measured arm poses.

Procedure (each step an OpenCV call, then one joint refinement):

1. ``cv2.calibrateCamera`` per camera: intrinsics (k1, k2, p1, p2; k3 fixed at 0) and the
   board pose in every view.
2. ``cv2.stereoCalibrate`` with the intrinsics fixed: the right camera relative to the left.
3. Registration, targets at known robot poses: every view gives the camera pose in the arm
   base frame as T_base_tcp (encoders + arm model) . T_tcp_board (the bracket drawing) .
   T_board_cam (step 1); their rotation/translation average starts step 4. (OpenCV 5's Python
   build no longer ships ``calibrateRobotWorldHandEye``; step 4 re-estimates the board's pose
   on the hand, so the bracket drawing only has to be right to a few mm and degrees.)
4. Bundle adjustment (scipy ``least_squares``) of both cameras' intrinsics and base-frame
   poses and the one board-on-hand pose, over every detected corner of every view.

The result is a :class:`StereoPair` posed in the base frame, which is what the detectors use.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from serpar.sim.calibration_board import CheckerboardConfig
from serpar.vision.camera import CameraModel, StereoPair
from serpar.vision.errors import CalibrationError

Pose = tuple[NDArray[np.float64], NDArray[np.float64]]
"""(rotation matrix, translation)."""
MIN_VIEWS = 6
DISTORTION_TERMS = {"none": 0, "k1": 1, "k1k2": 2, "k1k2p1p2": 4}
"""Lens models: how many of OpenCV's (k1, k2, p1, p2) are estimated (the rest held at 0)."""
_CV_FLAGS = {
    0: cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
    1: cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
    2: cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
    4: cv2.CALIB_FIX_K3,
}


@dataclass(frozen=True)
class Observation:
    """Corners of the board seen in one view; None where a camera did not find the board."""

    tcp_rot: NDArray[np.float64]
    tcp_pos: NDArray[np.float64]
    left: NDArray[np.float64] | None
    right: NDArray[np.float64] | None


@dataclass(frozen=True)
class PairCalibration:
    pair: StereoPair
    board_on_tcp: Pose
    rms_px: dict[str, float]
    """Reprojection RMS of each stage: 'left', 'right' (calibrateCamera), 'stereo', 'bundle'."""
    rectified_row_error_px: float
    """RMS vertical disparity of matched corners after stereoRectify (0 for a perfect pair)."""
    views_used: dict[str, int]


def _camera_init(name: str, obs: list[Observation], side: str, board: CheckerboardConfig,
                 size: tuple[int, int], n_dist: int) -> tuple[float, NDArray, NDArray, list[int], list[Pose]]:
    idx = [i for i, o in enumerate(obs) if getattr(o, side) is not None]
    if len(idx) < MIN_VIEWS:
        raise CalibrationError(f"camera {name}: board found in {len(idx)} views, need >= {MIN_VIEWS}")
    obj = [board.corner_points().astype(np.float32)] * len(idx)
    img = [getattr(obs[i], side).astype(np.float32) for i in idx]
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, size, None, None, flags=_CV_FLAGS[n_dist])
    poses = [(cv2.Rodrigues(r)[0], t.ravel()) for r, t in zip(rvecs, tvecs)]
    return float(rms), K, dist.ravel()[:5], idx, poses


def _mean_rotation(rots: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    """The rotation nearest (Frobenius) to the mean of `rots`."""
    u, _, vt = np.linalg.svd(np.sum(rots, axis=0))
    return u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt


def _registration_init(obs: list[Observation], idx: list[int], board_in_cam: list[Pose],
                       board_on_tcp: Pose) -> Pose:
    """Base -> camera from the board at known robot poses, taking the bracket drawing's board pose.

    Each view gives T_base_cam = T_base_tcp T_tcp_board T_board_cam; their average starts the
    bundle adjustment, which then re-estimates the board's pose on the hand with everything else.
    """
    r_tb, t_tb = board_on_tcp
    rots, poss = [], []
    for i, (r_cb, t_cb) in zip(idx, board_in_cam):
        r_bb = obs[i].tcp_rot @ r_tb  # base <- board
        p_bb = obs[i].tcp_rot @ t_tb + obs[i].tcp_pos
        r_bc = r_bb @ r_cb.T  # base <- camera
        rots.append(r_bc)
        poss.append(p_bb - r_bc @ t_cb)
    r_bc, p_bc = _mean_rotation(rots), np.mean(poss, axis=0)
    return r_bc.T, -r_bc.T @ p_bc


def _pack(K: NDArray, dist: NDArray, pose: Pose, n_dist: int) -> NDArray:
    return np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist[:n_dist], cv2.Rodrigues(pose[0])[0].ravel(), pose[1]]


def _unpack(p: NDArray, n_dist: int) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    K = np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1.0]])
    dist = np.zeros(5)
    dist[:n_dist] = p[4:4 + n_dist]
    return K, dist, p[4 + n_dist:7 + n_dist], p[7 + n_dist:10 + n_dist]


def _residuals(x: NDArray, obs: list[Observation], corners: NDArray, n_dist: int) -> NDArray:
    n = 10 + n_dist
    cams = (x[:n], x[n:2 * n])
    r_bt, t_bt = cv2.Rodrigues(x[2 * n:2 * n + 3])[0], x[2 * n + 3:2 * n + 6]
    res = []
    for o in obs:
        pts = (corners @ r_bt.T + t_bt) @ o.tcp_rot.T + o.tcp_pos  # board -> TCP -> base
        for cam, uv in zip(cams, (o.left, o.right)):
            if uv is None:
                continue
            K, dist, rvec, tvec = _unpack(cam, n_dist)
            proj, _ = cv2.projectPoints(pts, rvec, tvec, K, dist)
            res.append((proj.reshape(-1, 2) - uv).ravel())
    return np.concatenate(res)


def _camera_model(name: str, size: tuple[int, int], p: NDArray, n_dist: int) -> CameraModel:
    K, dist, rvec, tvec = _unpack(p, n_dist)
    r_cw = cv2.Rodrigues(rvec)[0]
    return CameraModel(name, size, K, dist, r_cw.T, -r_cw.T @ tvec)


def _rectified_row_error(pair: StereoPair, obs: list[Observation]) -> float:
    """RMS of the row difference of matched corners after cv2.stereoRectify (pixels)."""
    lc, rc = pair.left, pair.right
    r_rel = rc.rot.T @ lc.rot  # left camera -> right camera
    t_rel = (rc.rot.T @ (lc.pos - rc.pos)).reshape(3, 1)
    r1, r2, p1, p2, *_ = cv2.stereoRectify(lc.K, lc.dist, rc.K, rc.dist, lc.size, r_rel, t_rel, alpha=0)
    dy = []
    for o in obs:
        if o.left is not None and o.right is not None:
            yl = cv2.undistortPoints(o.left.reshape(-1, 1, 2), lc.K, lc.dist, R=r1, P=p1).reshape(-1, 2)[:, 1]
            yr = cv2.undistortPoints(o.right.reshape(-1, 1, 2), rc.K, rc.dist, R=r2, P=p2).reshape(-1, 2)[:, 1]
            dy.append(yl - yr)
    return float(np.sqrt(np.mean(np.concatenate(dy) ** 2))) if dy else float("nan")


def calibrate_pair(obs: list[Observation], board: CheckerboardConfig, size: tuple[int, int],
                   names: tuple[str, str], distortion: str = "k1k2p1p2") -> PairCalibration:
    """Calibrate a stereo pair and register it to the arm base frame (module docstring).

    `distortion` is the lens model (a key of DISTORTION_TERMS).
    """
    if distortion not in DISTORTION_TERMS:
        raise CalibrationError(f"distortion model {distortion!r}; valid: {', '.join(DISTORTION_TERMS)}")
    n_dist = DISTORTION_TERMS[distortion]
    rms: dict[str, float] = {}
    init = {}
    for name, side in zip(names, ("left", "right")):
        rms[side], K, dist, idx, poses = _camera_init(name, obs, side, board, size, n_dist)
        init[side] = (K, dist, idx, poses)
    both = [o for o in obs if o.left is not None and o.right is not None]
    if len(both) < MIN_VIEWS // 2:
        raise CalibrationError(f"pair {names}: the board was seen by both cameras in {len(both)} views")
    obj = [board.corner_points().astype(np.float32)] * len(both)
    (Kl, dl, _, _), (Kr, dr, _, _) = init["left"], init["right"]
    rms["stereo"] = float(cv2.stereoCalibrate(obj, [o.left.astype(np.float32) for o in both],
                                              [o.right.astype(np.float32) for o in both], Kl, dl, Kr, dr,
                                              size, flags=cv2.CALIB_FIX_INTRINSIC)[0])
    board_on_tcp = board.tcp_to_board()
    base_to_cam = {side: _registration_init(obs, init[side][2], init[side][3], board_on_tcp)
                   for side in ("left", "right")}
    x0 = np.r_[_pack(Kl, dl, base_to_cam["left"], n_dist), _pack(Kr, dr, base_to_cam["right"], n_dist),
               cv2.Rodrigues(board_on_tcp[0])[0].ravel(), board_on_tcp[1]]
    corners = board.corner_points()
    sol = least_squares(_residuals, x0, args=(obs, corners, n_dist), x_scale="jac", method="lm")
    if not sol.success:
        raise CalibrationError(f"pair {names}: bundle adjustment did not converge ({sol.message})")
    rms["bundle"] = float(np.sqrt(np.mean(sol.fun**2) * 2))
    n = 10 + n_dist
    pair = StereoPair(_camera_model(names[0], size, sol.x[:n], n_dist),
                      _camera_model(names[1], size, sol.x[n:2 * n], n_dist))
    board_on_tcp = (cv2.Rodrigues(sol.x[2 * n:2 * n + 3])[0], sol.x[2 * n + 3:2 * n + 6])
    views = {"left": len(init["left"][2]), "right": len(init["right"][2]), "both": len(both)}
    return PairCalibration(pair, board_on_tcp, rms, _rectified_row_error(pair, obs), views)
