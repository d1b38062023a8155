"""The camera sensors on Foxglove topics (docs/foxglove.md, docs/cameras.md): what each camera is, its frames and
its messages. Pure: plain values in, foxglove messages out.

Frames per camera ``cam_<name>`` (sent on ``/tf`` with the constant transforms): ``<parent> -> cam_<name>`` the
mount (body axes: x forward, y left, z up; its point cloud is in this frame, like the LiDAR's), ``cam_<name> ->
cam_<name>_optical`` the optical frame Foxglove's images and calibrations use (x right, y down, z forward), and
for a stereo pair ``cam_<name>_optical -> cam_<name>_right_optical`` (the baseline along x).

Topics per camera: ``/cam_<name>/rgb`` (and ``/right``) the colour images, ``/cam_<name>/calibration``
foxglove.CameraCalibration, ``/cam_<name>/depth`` foxglove.RawImage ``32FC1`` the measured planar depth (m, NaN
invalid), ``/cam_<name>/depth_exact`` the renderer's exact depth, ``/cam_<name>/labels`` ``mono8`` labels,
``/cam_<name>/points`` foxglove.PointCloud.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from foxglove.messages import CameraCalibration, RawImage

from .messages import stamp

__all__ = ["CameraInfo", "OPTICAL_FROM_BODY", "camera_infos", "calibration_msg", "float_image_msg",
           "mono_image_msg", "camera_frames", "CAMERA_ARRAY_PARTS"]

#: body axes (x forward, y left, z up) -> optical axes (x right, y down, z forward): the columns are the optical
#: axes in body coordinates
OPTICAL_FROM_BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
#: the camera array blocks the observers show: part -> topic suffix
CAMERA_ARRAY_PARTS = {"measured": "depth", "depth": "depth_exact", "labels": "labels", "points": "points"}


@dataclass(frozen=True)
class CameraInfo:
    """One camera sensor as the recorder needs it: ``name``, its ``parent`` body, ``parent_from_body`` (4, 4)
    (the mount), the pinhole ``K`` (3, 3; pixel centres at half-integers, as docs/cameras.md), ``width`` and
    ``height`` px, the stereo ``baseline_m`` (0 for one camera)."""

    name: str
    parent: str
    parent_from_body: np.ndarray
    K: np.ndarray
    width: int
    height: int
    baseline_m: float = 0.0

    @property
    def frame(self) -> str:
        return f"cam_{self.name}"


def camera_infos(scenario) -> tuple[CameraInfo, ...]:
    """Every camera sensor of ``scenario`` as the renderer draws it (the mock's scaled images included)."""
    from cosim.world.geometry import mount_transform
    from cosim.world.sensors import camera_pinhole, intrinsics_matrix

    out = []
    for name, cam in scenario.cameras.items():
        pin = camera_pinhole(cam, scenario)
        out.append(CameraInfo(name, cam.mount.parent, np.asarray(mount_transform(cam.mount), float),
                              intrinsics_matrix(pin), pin.width, pin.height, float(getattr(cam, "baseline_m", 0.0))))
    return tuple(out)


def camera_frames(info: CameraInfo) -> list[tuple[str, str, np.ndarray]]:
    """The camera's constant transforms (parent, child, parent_from_child (4, 4))."""
    body_from_optical = np.eye(4)
    body_from_optical[:3, :3] = OPTICAL_FROM_BODY
    frames = [(info.parent, info.frame, info.parent_from_body),
              (info.frame, f"{info.frame}_optical", body_from_optical)]
    if info.baseline_m > 0.0:
        right = np.eye(4)
        right[0, 3] = info.baseline_m
        frames.append((f"{info.frame}_optical", f"{info.frame}_right_optical", right))
    return frames


def calibration_msg(t_ns: int, info: CameraInfo, frame_id: str) -> CameraCalibration:
    """CameraCalibration of the camera (no distortion). Foxglove (and OpenCV, ROS) put pixel centres at integers,
    so the principal point is ours less half a pixel; P = [K | 0]."""
    k = np.array(info.K, float)
    k[0, 2] -= 0.5
    k[1, 2] -= 0.5
    p = np.zeros((3, 4))
    p[:, :3] = k
    return CameraCalibration(timestamp=stamp(t_ns), frame_id=frame_id, width=int(info.width), height=int(info.height),
                             distortion_model="plumb_bob", D=[0.0] * 5, K=k.ravel().tolist(),
                             R=np.eye(3).ravel().tolist(), P=p.ravel().tolist())


def float_image_msg(t_ns: int, image: np.ndarray, frame_id: str) -> RawImage:
    """RawImage ``32FC1`` of an (H, W) float32 image (depth m, NaN invalid), its bytes unchanged."""
    h, w = image.shape
    data = np.ascontiguousarray(image, dtype="<f4")
    return RawImage(timestamp=stamp(t_ns), frame_id=frame_id, width=w, height=h, encoding="32FC1", step=4 * w,
                    data=data.tobytes())


def mono_image_msg(t_ns: int, image: np.ndarray, frame_id: str) -> RawImage:
    """RawImage ``mono8`` of an (H, W) uint8 image (labels)."""
    h, w = image.shape
    return RawImage(timestamp=stamp(t_ns), frame_id=frame_id, width=w, height=h, encoding="mono8", step=w,
                    data=np.ascontiguousarray(image, dtype=np.uint8).tobytes())
