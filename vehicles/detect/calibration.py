"""A camera's calibration: intrinsics, lens distortion and where it sits on the body, in OpenCV's YAML format.

The file is what OpenCV's own calibration tools write (`cv::FileStorage`, `%YAML:1.0`), with two more nodes
for the mount:

    image_width: 2040
    image_height: 1086
    camera_matrix: !!opencv-matrix        # 3 x 3: fx 0 cx / 0 fy cy / 0 0 1, pixels
    distortion_coefficients: !!opencv-matrix   # 1 x 4, 5, 8, 12 or 14: k1 k2 p1 p2 [k3 ...], OpenCV's model
    camera_to_body_rotation: !!opencv-matrix   # 3 x 3: columns are the camera's x (right), y (down) and
                                               # z (optical axis) in the body's forward-left-up axes
    camera_to_body_translation_m: !!opencv-matrix  # 3 x 1: the optical centre in the body frame, metres

So a file from `calibrateCamera` works after the two mount nodes are added (`skyring detect
--write-calibration` writes a complete template). A missing or inconsistent node is a clear error naming the
node and the file. The default (`Calibration.from_camera_params`) is the simulated camera of
vehicles/camera.py: 45 degrees down, 0.18 m ahead of the body centre, no distortion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controller.messages import frozen_array
from vehicles.camera import CameraParams, CameraPose, body_rotation


def _freeze(obj: object, name: str, shape: tuple[int, ...]) -> None:
    object.__setattr__(obj, name, frozen_array(getattr(obj, name), shape, name))


def mount_rotation(pitch_down_rad: float) -> np.ndarray:
    """(3, 3) camera-to-body rotation of a camera looking forward, pitched pitch_down_rad below the body's
    forward axis (columns: camera x, y, z in forward-left-up body axes)."""
    c, s = math.cos(pitch_down_rad), math.sin(pitch_down_rad)
    return np.array([[0.0, -1.0, 0.0], [-s, 0.0, -c], [c, 0.0, -s]]).T


class CalibrationError(ValueError):
    """A calibration file that cannot be used; the message names the file and the node."""


@dataclass(frozen=True, eq=False)
class Calibration:
    """width_px, height_px: the image size the intrinsics belong to; camera_matrix (3, 3) pixels;
    distortion (K,) OpenCV coefficients (K in 4, 5, 8, 12, 14; zeros for none); camera_to_body_rotation
    (3, 3) proper rotation, columns = camera axes in body forward-left-up axes; camera_to_body_translation_m
    (3,) the optical centre in the body frame."""

    width_px: int
    height_px: int
    camera_matrix: np.ndarray
    distortion: np.ndarray
    camera_to_body_rotation: np.ndarray
    camera_to_body_translation_m: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self, "camera_matrix", (3, 3))
        _freeze(self, "distortion", (-1,))
        _freeze(self, "camera_to_body_rotation", (3, 3))
        _freeze(self, "camera_to_body_translation_m", (3,))
        if not (self.width_px > 0 and self.height_px > 0):
            raise CalibrationError(f"image size must be positive, got {self.width_px} x {self.height_px}")
        k = self.camera_matrix
        if not (np.all(np.isfinite(k)) and k[0, 0] > 0 and k[1, 1] > 0 and np.allclose(k[2], [0, 0, 1])):
            raise CalibrationError(
                "camera_matrix must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0"
            )
        if self.distortion.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(self.distortion)):
            raise CalibrationError(
                "distortion_coefficients must hold 4, 5, 8, 12 or 14 finite numbers, "
                f"got {self.distortion.size}"
            )
        r = self.camera_to_body_rotation
        if not (np.allclose(r.T @ r, np.eye(3), atol=1e-6) and abs(np.linalg.det(r) - 1.0) < 1e-6):
            raise CalibrationError(
                "camera_to_body_rotation must be a proper rotation matrix (R^T R = I, det 1)"
            )
        if not np.all(np.isfinite(self.camera_to_body_translation_m)):
            raise CalibrationError("camera_to_body_translation_m must be finite")

    @property
    def fx_px(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def fy_px(self) -> float:
        return float(self.camera_matrix[1, 1])

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.distortion != 0.0))

    @classmethod
    def from_camera_params(cls, params: CameraParams | None = None) -> Calibration:
        """The simulated camera (vehicles/camera.py) as a calibration: pinhole, no distortion."""
        p = params or CameraParams()
        return cls(
            width_px=p.width_px,
            height_px=p.height_px,
            camera_matrix=np.array([[p.fx_px, 0.0, p.cx_px], [0.0, p.fy_px, p.cy_px], [0.0, 0.0, 1.0]]),
            distortion=np.zeros(5),
            camera_to_body_rotation=mount_rotation(p.pitch_down_rad),
            camera_to_body_translation_m=np.array([p.offset_forward_m, 0.0, 0.0]),
        )

    def camera_pose(
        self, *, body_position_m: np.ndarray, yaw_rad: float, pitch_rad: float = 0.0, roll_rad: float = 0.0
    ) -> CameraPose:
        """The camera's world pose for a body at body_position_m (3,) ENU with the given attitude (aviation
        sense, as vehicles.camera.body_rotation); equals vehicles.camera.camera_pose for the default."""
        r_wb = body_rotation(yaw_rad=yaw_rad, pitch_rad=pitch_rad, roll_rad=roll_rad)
        rotation = self.camera_to_body_rotation.T @ r_wb.T  # world -> camera
        position = np.asarray(body_position_m, dtype=float) + r_wb @ self.camera_to_body_translation_m
        return CameraPose(position_m=position, rotation=rotation)

    def normalized(self, pixels: np.ndarray) -> np.ndarray:
        """(M, 2) undistorted normalised image coordinates (x/z, y/z, camera frame) of raw pixels (M, 2).

        Pinhole inversion when there is no distortion; otherwise OpenCV's iterative undistortPoints.
        """
        pts = np.asarray(pixels, dtype=float).reshape(-1, 2)
        if not self.has_distortion:
            k = self.camera_matrix
            y = (pts[:, 1] - k[1, 2]) / k[1, 1]
            x = (pts[:, 0] - k[0, 2] - k[0, 1] * y) / k[0, 0]
            return np.stack([x, y], axis=1)
        import cv2  # only for a distorted lens; the agent needs no OpenCV otherwise

        out = cv2.undistortPoints(pts.reshape(-1, 1, 2), self.camera_matrix, self.distortion)
        return np.asarray(out, dtype=float).reshape(-1, 2)

    def save(self, path: str | Path) -> None:
        """Write this calibration as an OpenCV YAML file."""
        import cv2

        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise CalibrationError(f"{path}: cannot be written")
        try:
            fs.write("image_width", int(self.width_px))
            fs.write("image_height", int(self.height_px))
            fs.write("camera_matrix", np.array(self.camera_matrix))
            fs.write("distortion_coefficients", np.array(self.distortion).reshape(1, -1))
            fs.write("camera_to_body_rotation", np.array(self.camera_to_body_rotation))
            fs.write(
                "camera_to_body_translation_m", np.array(self.camera_to_body_translation_m).reshape(3, 1)
            )
        finally:
            fs.release()

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read an OpenCV YAML (or XML/JSON) calibration file; CalibrationError naming the file and node."""
        import cv2

        p = Path(path)
        if not p.is_file():
            raise CalibrationError(f"{p}: no such calibration file")
        try:
            fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
        except cv2.error as exc:
            raise CalibrationError(f"{p}: not an OpenCV YAML/XML/JSON file ({exc.msg.strip()})") from exc
        if not fs.isOpened():
            raise CalibrationError(f"{p}: not an OpenCV YAML/XML/JSON file")
        try:

            def matrix(name: str) -> np.ndarray:
                node = fs.getNode(name)
                if node.empty():
                    raise CalibrationError(f"{p}: node {name!r} is missing")
                mat = node.mat()
                if mat is None:
                    raise CalibrationError(f"{p}: node {name!r} is not an !!opencv-matrix")
                return np.asarray(mat, dtype=float)

            def integer(name: str) -> int:
                node = fs.getNode(name)
                if node.empty() or not node.isInt():
                    raise CalibrationError(f"{p}: node {name!r} is missing or not an integer")
                return int(node.real())

            try:
                return cls(
                    width_px=integer("image_width"),
                    height_px=integer("image_height"),
                    camera_matrix=matrix("camera_matrix"),
                    distortion=matrix("distortion_coefficients").ravel(),
                    camera_to_body_rotation=matrix("camera_to_body_rotation"),
                    camera_to_body_translation_m=matrix("camera_to_body_translation_m").ravel(),
                )
            except CalibrationError as exc:
                if str(exc).startswith(str(p)):
                    raise
                raise CalibrationError(f"{p}: {exc}") from exc
            except ValueError as exc:
                raise CalibrationError(f"{p}: {exc}") from exc
        finally:
            fs.release()
