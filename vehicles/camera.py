"""The body-fixed camera of a MAV: pose, pinhole projection, and what it sees of the person.

The camera is rigidly attached to the body, pitched `pitch_down_rad` below the body's forward axis and
`offset_forward_m` ahead of its centre (paper Sec. II and its Gazebo set-up), so its view tilts with the
body's roll and pitch and turns with its yaw. Image convention: u to the right, v down, pixel (0, 0) the
top-left corner; camera frame x right, y down, z along the optical axis.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from controller.messages import Obstacle, read_only


@dataclass(frozen=True)
class CameraParams:
    """Paper intrinsics (2040 x 1086 px, fx = fy = 1470.33 px, principal point (1020.5, 543.5) px) and
    mount (45 degrees down, 0.18 m ahead of the body centre)."""

    width_px: int = 2040
    height_px: int = 1086
    fx_px: float = 1470.33
    fy_px: float = 1470.33
    cx_px: float = 1020.5
    cy_px: float = 543.5
    pitch_down_rad: float = math.radians(45.0)
    offset_forward_m: float = 0.18

    @property
    def center_px(self) -> np.ndarray:
        """(2,) the image centre (width/2, height/2), used for the centre-offset metric."""
        return np.array([self.width_px / 2.0, self.height_px / 2.0])


def body_rotation(*, yaw_rad: float, pitch_rad: float = 0.0, roll_rad: float = 0.0) -> np.ndarray:
    """(3, 3) body-to-world rotation; columns are the body's forward, left and up axes in ENU.

    yaw_rad: ENU heading; pitch_rad > 0 nose up and roll_rad > 0 right side down (the aviation sense, so the
    numbers mean the same as PX4's): R = Rz(yaw) Ry(-pitch) Rx(roll) for forward-left-up body axes.
    """
    return body_rotations([(yaw_rad, pitch_rad, roll_rad)])[0]


def body_rotations(attitudes: Sequence[tuple[float, float, float]]) -> np.ndarray:
    """(N, 3, 3) the body_rotation of each (yaw_rad, pitch_rad, roll_rad), by one call of scipy's.

    A Rotation costs some 15 us of Python per call, whatever N, and computes each row of a stack exactly as
    it computes a single rotation (tests/vehicles/test_camera.py holds it to the bit), so a world taking
    several frames at once makes their rotations together.
    """
    angles = np.array([[yaw, -pitch, roll] for yaw, pitch, roll in attitudes], dtype=float).reshape(-1, 3)
    return Rotation.from_euler("ZYX", angles).as_matrix()


def attitude_from_acceleration(
    *, acceleration_mps2: np.ndarray, yaw_rad: float, gravity_mps2: float = 9.81
) -> tuple[float, float]:
    """(roll_rad, pitch_rad) of a multirotor whose thrust produces acceleration_mps2 (3,) at heading yaw_rad.

    The thrust axis (body up) is along a + g z; inverting body_rotation's third column in the yaw frame gives
    roll = -asin(n_left), pitch = -atan2(n_forward, n_up).
    """
    n = np.array([acceleration_mps2[0], acceleration_mps2[1], acceleration_mps2[2] + gravity_mps2])
    norm = float(np.linalg.norm(n))
    if norm < 1e-6:
        return 0.0, 0.0
    n /= norm
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    forward = c * n[0] + s * n[1]
    left = -s * n[0] + c * n[1]
    return -math.asin(max(-1.0, min(1.0, left))), -math.atan2(forward, n[2])


@dataclass(frozen=True, eq=False)
class CameraPose:
    """position_m (3,) of the optical centre; rotation (3, 3) world-to-camera (rows: camera x, y, z in
    ENU)."""

    position_m: np.ndarray
    rotation: np.ndarray


def camera_pose(
    *,
    body_position_m: np.ndarray,
    yaw_rad: float,
    pitch_rad: float = 0.0,
    roll_rad: float = 0.0,
    params: CameraParams = CameraParams(),
) -> CameraPose:
    """The camera's pose for a body at body_position_m (3,) with the given attitude."""
    r_wb = body_rotation(yaw_rad=yaw_rad, pitch_rad=pitch_rad, roll_rad=roll_rad)
    return mounted_camera_pose(body_position_m=body_position_m, body_to_world=r_wb, params=params)


def mounted_camera_pose(
    *, body_position_m: np.ndarray, body_to_world: np.ndarray, params: CameraParams = CameraParams()
) -> CameraPose:
    """The camera's pose for a body at body_position_m (3,) turned by body_to_world (3, 3), body_rotation's
    matrix."""
    rotation = _camera_in_body(params.pitch_down_rad) @ body_to_world.T
    position = np.asarray(body_position_m, dtype=float) + body_to_world[:, 0] * params.offset_forward_m
    return CameraPose(position_m=position, rotation=rotation)


@functools.cache
def _camera_in_body(pitch_down_rad: float) -> np.ndarray:
    """(3, 3) the camera's axes in body (forward-left-up) coordinates: optical axis pitched down, image down,
    image right. Made once per mount angle (read-only), as every frame of every camera asks for it."""
    c, s = math.cos(pitch_down_rad), math.sin(pitch_down_rad)
    return read_only(np.array([[0.0, -1.0, 0.0], [-s, 0.0, -c], [c, 0.0, -s]]))


def _camera_frame(points_m: np.ndarray, pose: CameraPose) -> np.ndarray:
    """(M, 3) world points (M, 3) in the camera frame: x right, y down, z the depth along the optical axis."""
    return (np.asarray(points_m, dtype=float) - pose.position_m) @ pose.rotation.T


def project(
    points_m: np.ndarray, pose: CameraPose, params: CameraParams = CameraParams()
) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of world points (M, 3): pixels (M, 2) and depth along the optical axis (M,).

    Points behind the camera (depth <= 0) get NaN pixels.
    """
    pc = _camera_frame(points_m, pose)
    pixels = [_pixel(point, params) for point in pc.tolist()]
    return np.array(pixels, dtype=float).reshape(-1, 2), pc[:, 2]


def _pixel(point: Sequence[float], params: CameraParams) -> tuple[float, float]:
    """(u, v) of the camera-frame point (x, y, depth), NaN behind the camera (depth <= 1e-9). Plain floats:
    a frame projects three points, and numpy's per-call cost was most of it; the operations are numpy's
    elementwise ones, in the same order, so the pixels are the same to the bit."""
    x, y, depth = point
    if not depth > 1e-9:
        return math.nan, math.nan
    return params.fx_px * x / depth + params.cx_px, params.fy_px * y / depth + params.cy_px


def inside_image(pixels: np.ndarray, params: CameraParams = CameraParams()) -> np.ndarray:
    """(M,) bool: finite pixels (M, 2) inside [0, width] x [0, height]."""
    return np.array([_inside(pixel, params) for pixel in np.asarray(pixels).tolist()], dtype=bool)


def _inside(pixel: Sequence[float], params: CameraParams) -> bool:
    """Whether pixel (u, v) is finite and inside [0, width] x [0, height]."""
    u, v = pixel
    return (
        math.isfinite(u) and math.isfinite(v) and 0.0 <= u <= params.width_px and 0.0 <= v <= params.height_px
    )


def line_of_sight_clear(a_m: np.ndarray, b_m: np.ndarray, obstacles: tuple[Obstacle, ...]) -> bool:
    """True when the segment a (3,) -> b (3,) passes no vertical cylinder below its top.

    For each trunk the segment's horizontal closest approach to the axis is compared with the radius, at the
    segment's height there (exact for the thin trunks of the arena, where the segment is nearly straight over
    the trunk's width).
    """
    if not obstacles:
        return True
    centers, radii, tops = _trunks(obstacles)
    d = b_m[:2] - a_m[:2]
    dd = float(d @ d)
    if dd < 1e-12:
        t = np.zeros(len(obstacles))
    else:
        t = np.clip(((centers - a_m[:2]) @ d) / dd, 0.0, 1.0)
    closest = a_m[:2] + t[:, None] * d
    dist = np.hypot(closest[:, 0] - centers[:, 0], closest[:, 1] - centers[:, 1])
    z = a_m[2] + t * (b_m[2] - a_m[2])
    return not bool(np.any((dist < radii) & (z < tops)))


@functools.lru_cache(maxsize=16)
def _trunks(obstacles: tuple[Obstacle, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (M, 2), radii (M,) and tops (M,) of the obstacles, made once per tuple of them (an obstacle
    hashes by identity): a world's trunks stand still, and building these was half of every line-of-sight
    check."""
    centers = read_only(np.array([o.center_m for o in obstacles]))
    radii = read_only(np.array([o.radius_m for o in obstacles]))
    tops = read_only(np.array([o.height_m for o in obstacles]))
    return centers, radii, tops


@dataclass(frozen=True, eq=False)
class FrameView:
    """What one camera frame shows of the person.

    in_frame: head and feet both project inside the image; visible: in_frame and no trunk blocks the line of
    sight to the body centre; center_px (2,): the body centre's pixel (NaN when behind the camera);
    center_offset_px: its distance from the image centre (NaN when behind the camera).
    """

    in_frame: bool
    visible: bool
    center_px: np.ndarray
    center_offset_px: float


def view_person(
    *,
    pose: CameraPose,
    center_m: np.ndarray,
    feet_m: np.ndarray,
    head_m: np.ndarray,
    obstacles: tuple[Obstacle, ...],
    params: CameraParams = CameraParams(),
) -> FrameView:
    """Project the person's centre, feet and head (each (3,)) and check the line of sight to the centre."""
    center, feet, head = _camera_frame(np.stack([center_m, feet_m, head_m]), pose).tolist()
    u, v = _pixel(center, params)
    in_frame = _inside(_pixel(feet, params), params) and _inside(_pixel(head, params), params)
    visible = in_frame and line_of_sight_clear(pose.position_m, np.asarray(center_m, dtype=float), obstacles)
    cu, cv = params.center_px.tolist()
    offset = float(np.hypot(u - cu, v - cv))
    return FrameView(in_frame=in_frame, visible=visible, center_px=np.array([u, v]), center_offset_px=offset)
