"""A real AprilTag detector on grey images: OpenCV's aruco ``DICT_APRILTAG_36h11`` (the package's only ``cv2``).

OpenCV is an extra (``pip install 'bearnav[camera]'``); it is imported on first use, so the rest of
the package (and a robot running :mod:`bearnav_cli.runtime`) never needs it. ``docs/camera.md``
says why OpenCV's detector rather than ``pupil-apriltags``.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.runtime.camera import Detection, tag_pose_from_opencv
from bearnav_cli.runtime.camera_model import Intrinsics

__all__ = ["TAG36H11_IDS", "detect", "detector", "estimate_pose", "tag36h11_cells"]

#: Ids of the tag36h11 family (OpenCV's dictionary has the 587 codes of AprilTag's).
TAG36H11_IDS = 587


def _cv2() -> Any:
    try:
        import cv2
    except ImportError as exc:
        raise InvalidParamsError("--camera render needs OpenCV: pip install 'bearnav[camera]'", field="camera") from exc
    if not hasattr(cv2, "aruco") or not hasattr(cv2.aruco, "ArucoDetector"):
        raise InvalidParamsError(
            f"OpenCV {cv2.__version__} has no aruco.ArucoDetector: pip install "
            "'bearnav[camera]' (opencv-python-headless >= 4.8)",
            field="camera",
        )
    return cv2


@functools.lru_cache(maxsize=1)
def _dictionary() -> Any:
    cv2 = _cv2()
    return cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)


def tag36h11_cells(tag_id: int) -> np.ndarray:
    """The 8 × 8 cells of a tag36h11 tag (black border included), 0 black and 1 white, top row first.

    OpenCV's own rendering of its dictionary entry, so what is drawn is what its detector decodes.
    """
    if not 0 <= int(tag_id) < TAG36H11_IDS:
        raise InvalidParamsError(f"tag36h11 has ids 0 to {TAG36H11_IDS - 1}, got {tag_id}", field="tag_id")
    cv2 = _cv2()
    cells = cv2.aruco.generateImageMarker(_dictionary(), int(tag_id), 8, borderBits=1)
    return (np.asarray(cells) > 127).astype(np.uint8)


def detector(refine: bool = True) -> Any:
    """An ``cv2.aruco.ArucoDetector`` for tag36h11, with sub-pixel corner refinement when ``refine``."""
    cv2 = _cv2()
    params = cv2.aruco.DetectorParameters()
    if refine:
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        params.cornerRefinementWinSize = 3  # a small tag's corner window must stay inside its border cell
        params.cornerRefinementMaxIterations = 50
        params.cornerRefinementMinAccuracy = 0.01
    # small tags far away (measured on rendered kitchen frames: with these, 3 in 4 tags of 8–12 px
    # across are decoded, against 2 in 5 with OpenCV's defaults): sample 8 px per cell when
    # unwarping, correct up to tag36h11's limit (5 of its 11 bits of minimum distance; a wrong id
    # is rarer than a missed tag, and observe() drops ids not in the plan), accept quads of 8 px
    params.perspectiveRemovePixelPerCell = 8
    params.errorCorrectionRate = 1.0
    params.minMarkerPerimeterRate = 0.02
    return cv2.aruco.ArucoDetector(_dictionary(), params)


def detect(image: np.ndarray, found: Any = None) -> list[Detection]:
    """The tags in a grey image (uint8, (H, W)): ids and corner pixels (OpenCV's order: clockwise in the
    image from the top-left corner of the upright tag), without poses.

    Parameters
    ----------
    image : ndarray of uint8, shape (H, W)
        The grey frame (0 black, 255 white).
    found : cv2.aruco.ArucoDetector, optional
        A detector from :func:`detector` (made once and reused: building one is not free).
    """
    found = detector() if found is None else found
    corners, ids, _ = found.detectMarkers(np.ascontiguousarray(image))
    if ids is None:
        return []
    return [
        Detection(int(i), np.asarray(c, float).reshape(4, 2)) for c, i in zip(corners, ids.reshape(-1), strict=True)
    ]


def estimate_pose(detection: Detection, intrinsics: Intrinsics, tag_size: float) -> Detection:
    """The detection with its pose (AprilTag convention) by ``cv2.solvePnP`` (``SOLVEPNP_SQPNP``).

    SQPnP is globally optimal; ``SOLVEPNP_IPPE_SQUARE``, made for markers, returned a wrong pose
    (reprojection error of tens of pixels) on exactly frontal noise-free rendered tags.

    Parameters
    ----------
    detection : Detection
        The tag found; its ``corners`` (px) must be in OpenCV's order (as :func:`detect` returns them).
    intrinsics : Intrinsics
        The camera matrix (``fx``, ``fy``, ``cx``, ``cy``, px) and distortion the corners were seen with.
    tag_size : float
        Edge of the tag's black square (metres): the scale of the pose's translation.

    Returns
    -------
    Detection
        ``detection`` with its ``pose``, or ``detection`` unchanged when ``solvePnP`` fails.
    """
    cv2 = _cv2()
    s = 0.5 * float(tag_size)
    model = np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])  # OpenCV's marker frame, y up
    k = np.array([[intrinsics.fx, 0.0, intrinsics.cx], [0.0, intrinsics.fy, intrinsics.cy], [0.0, 0.0, 1.0]])
    d = np.array(intrinsics.distortion, float) if intrinsics.distortion else np.zeros(5)
    ok, rvec, tvec = cv2.solvePnP(model, detection.corners.astype(np.float64), k, d, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return detection
    return Detection(detection.tag_id, detection.corners, tag_pose_from_opencv(rvec.reshape(3), tvec.reshape(3)))
