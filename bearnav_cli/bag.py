"""ROS 2 bags of ``bearnav simulate`` runs, for RViz 2 and Foxglove (docs/runtime.md "ROS 2 bags").

The only module that imports ``rosbags`` (the ``bearnav[ros]`` extra), lazily: the rest of
bearnav works without it. :func:`write` turns a :class:`~bearnav_cli.datatypes.Simulation`
(``sim.npz`` copies the plan's tree, cells and map, so it is enough) into a bag in standard
message types, every message in the frame ``map`` (map units, metres in the examples):

- ``/bearnav/markers`` ``visualization_msgs/msg/MarkerArray``, one message at ``t0``, offered
  transient-local ("latched"): the bounds, the obstacles as drawn (``obstacles``) and inflated by
  the robot radius (``inflated``) as closed LINE_STRIP rings, one per ring; the cells as closed
  LINE_STRIPs coloured by synthesis status (``cells``, marker id = cell index); the tags as CUBEs
  (``tags``) with their ids as TEXT_VIEW_FACING (``tag_ids``); the tree as one LINE_LIST
  (``tree``); the goal as a SPHERE (``goal``); every run's trajectory as a LINE_STRIP coloured by
  its outcome (``runs``, marker id = run index).
- ``/bearnav/path`` ``nav_msgs/msg/Path``, one message per run, stamped when its run begins.
- ``/bearnav/pose`` ``geometry_msgs/msg/PoseStamped``, one message per trajectory point.

Time: point ``p`` of ``trajectory_coords`` (run ``r``'s step ``k`` is ``p = offsets[r] + k``)
is stamped ``t0 + p·dt``: the runs play one after another, each at its simulated speed. The
orientation is the yaw ``trajectory_heading[p]`` about +z.

A ``.mcap`` path is written as one self-contained MCAP file (the rosbag2 metadata is inside,
chunks compressed with zstd; Foxglove opens it, ``ros2 bag play`` reads it); a path without an
extension as a ROS 2 bag folder (``metadata.yaml`` and ``NAME.mcap``). The bag is written in a
temp folder next to it (``artifacts.staging_folder``: a killed run's is removed by the next) and
renamed into place, so a failure leaves nothing under the real name. Only a bag bearnav wrote is
replaced (``artifacts.written_by``: the ``bearnav.map`` custom data every bag carries; a bag
folder holding anything else is someone's); ``--force`` replaces any ``.mcap`` file, never a
folder that is not such a bag.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from bearnav_cli import artifacts
from bearnav_cli.datatypes import CellStatus, Simulation
from bearnav_cli.errors import InvalidParamsError, OutputPathError
from bearnav_cli.palette import OUTCOME_COLORS, ROLE_COLORS, STATUS_COLORS, rgba

__all__ = ["FRAME", "SUFFIXES", "TOPICS", "check_path", "write"]

log = logging.getLogger(__name__)

#: Topic -> message type, in the order they are added to the bag.
TOPICS = {
    "/bearnav/markers": "visualization_msgs/msg/MarkerArray",
    "/bearnav/path": "nav_msgs/msg/Path",
    "/bearnav/pose": "geometry_msgs/msg/PoseStamped",
}
#: The frame of every message (the map's own frame, map units).
FRAME = "map"
#: Accepted path suffixes: one MCAP file, or none (a ROS 2 bag folder).
SUFFIXES = (".mcap", "")
#: Message definitions: ROS 2 Jazzy's (Humble, Iron, Kilted and Jazzy share them for these types).
STORE = "ros2_jazzy"

INSTALL_HINT = "writing ROS 2 bags needs the rosbags package: pip install 'bearnav[ros]'"

#: RGBA of each cell status: the figures' colours (:data:`bearnav_cli.palette.STATUS_COLORS`), opaque enough for lines.
STATUS_RGBA = {
    status: rgba(color, 1.0 if status == CellStatus.SOLVER_FAILURE else 0.9) for status, color in STATUS_COLORS.items()
}
#: RGBA of each run outcome: the figures' colours (:data:`bearnav_cli.palette.OUTCOME_COLORS`).
OUTCOME_RGBA = {outcome: rgba(color) for outcome, color in OUTCOME_COLORS.items()}


def _rosbags(option: str | None = "--bag") -> Any:
    """The rosbags pieces :func:`write` needs, or a one-line error saying how to install them."""
    try:
        from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise InvalidParamsError(INSTALL_HINT, field=option) from exc

    def qos(durability: Any) -> Any:
        zero = QosTime(0, 0)  # 0: the middleware's default (infinite)
        return Qos(
            QosHistory.KEEP_LAST,
            1 if durability is QosDurability.TRANSIENT_LOCAL else 10,
            QosReliability.RELIABLE,
            durability,
            zero,
            zero,
            QosLiveliness.AUTOMATIC,
            zero,
            False,
        )

    return {
        "Writer": Writer,
        "mcap": StoragePlugin.MCAP,
        "zstd": (CompressionMode.STORAGE, CompressionFormat.ZSTD),  # zstd chunks, as MCAP readers expect
        "typestore": get_typestore(Stores(STORE)),
        "latched": qos(QosDurability.TRANSIENT_LOCAL),
        "volatile": qos(QosDurability.VOLATILE),
    }


def check_path(path: str | os.PathLike, option: str | None = "--bag", force: bool = False) -> Path:
    """Refuse a bag path before any work; return it as a :class:`~pathlib.Path`.

    Refused: a suffix other than ``.mcap`` (lower case: rosbags reads no other) or none, a missing
    or unwritable folder, a ``.mcap`` path that is a folder or a file bearnav did not write (unless
    ``force``), an extension-less path that is a file or a folder other than a bag bearnav wrote or
    an empty one (even with ``force``: a folder is replaced whole), and a missing ``rosbags``.

    Parameters
    ----------
    path : str or os.PathLike
        ``NAME.mcap`` or ``NAME``, as the user gave it.
    option : str or None, default "--bag"
        The option named in errors.
    force : bool, default False
        Replace a ``.mcap`` file bearnav did not write (the user's ``--force``).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputPathError, InvalidParamsError
    """
    path = _checked_path(path, option, force)
    _rosbags(option)
    return path


def _checked_path(path: str | os.PathLike, option: str | None, force: bool) -> Path:
    """:func:`check_path` without the rosbags check (:func:`write` imports rosbags once itself)."""
    path = Path(path)
    suffix = path.suffix
    if path.name in ("", ".", ".."):
        raise OutputPathError("give the bag a name (NAME.mcap or NAME)", file=str(path), option=option)
    if suffix.lower() == ".mcap" and suffix != ".mcap":
        raise OutputPathError(
            f"extension {suffix!r}: write .mcap in lower case (rosbags reads only .mcap files)",
            file=str(path),
            option=option,
        )
    if suffix not in SUFFIXES:
        raise OutputPathError(
            f"extension {path.suffix!r}: expected .mcap (one MCAP file) or no extension (a ROS 2 bag folder)",
            file=str(path),
            option=option,
        )
    folder = path.parent
    if not folder.is_dir():
        what = "is a file, not a folder" if folder.exists() else "does not exist (create it first)"
        raise OutputPathError(f"the folder {folder} {what}", file=str(path), option=option)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputPathError(f"the folder {folder} is not writable", file=str(path), option=option)
    if suffix == ".mcap":
        if path.is_dir():
            raise OutputPathError("is a folder; give a new .mcap file name", file=str(path), option=option)
        if path.exists() and not path.is_file():
            raise OutputPathError("exists and is not a regular file", file=str(path), option=option)
        artifacts.check_overwrite(path, "bag", force=force, option=option)
    elif path.is_symlink():
        raise OutputPathError("is a symbolic link; give a new name", file=str(path), option=option)
    elif path.exists():
        if not path.is_dir():
            raise OutputPathError(
                "is a file; a bag without an extension is a folder (or give NAME.mcap)", file=str(path), option=option
            )
        if any(path.iterdir()) and artifacts.written_by(path) != artifacts.Origin("bag"):
            raise OutputPathError(
                "is a folder but not a ROS 2 bag written by bearnav (metadata.yaml and MCAP "
                "files only); give a new name",
                file=str(path),
                option=option,
            )
    return path


def _stamp(ns: int, types: dict) -> Any:
    return types["builtin_interfaces/msg/Time"](sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def _header(ns: int, types: dict) -> Any:
    return types["std_msgs/msg/Header"](stamp=_stamp(ns, types), frame_id=FRAME)


def _pose(x: float, y: float, yaw: float, types: dict) -> Any:
    point = types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0)
    half = 0.5 * float(yaw)
    quaternion = types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(half), w=math.cos(half))
    return types["geometry_msgs/msg/Pose"](position=point, orientation=quaternion)


def stamps_ns(sim: Simulation, t0_ns: int = 0) -> np.ndarray:
    """The stamp (ns) of every trajectory point: ``t0 + p·dt``, shape (P,) int64."""
    return t0_ns + np.rint(np.arange(len(sim.trajectory_coords)) * sim.dt * 1e9).astype(np.int64)


def _markers(sim: Simulation, ns: int, types: dict) -> list:
    """Every marker of ``/bearnav/markers`` (module docstring), in the map frame at time ``ns``."""
    point_t, color_t = types["geometry_msgs/msg/Point"], types["std_msgs/msg/ColorRGBA"]
    marker_t, vector_t = types["visualization_msgs/msg/Marker"], types["geometry_msgs/msg/Vector3"]
    duration = types["builtin_interfaces/msg/Duration"]
    texture = types["sensor_msgs/msg/CompressedImage"]
    mesh = types["visualization_msgs/msg/MeshFile"]
    bounds = np.asarray(sim.map.bounds, float)
    size = math.hypot(*(bounds[2:] - bounds[:2]))  # marker sizes scale with the map
    width = 0.003 * size
    markers: list = []
    counts: dict[str, int] = {}

    def add(
        namespace: str,
        kind: int,
        points: Any = (),
        color: tuple = (0.0, 0.0, 0.0, 1.0),
        scale: tuple = (width, 0.0, 0.0),
        at: tuple = (0.0, 0.0),
        text: str = "",
    ) -> None:
        ident = counts.get(namespace, 0)
        counts[namespace] = ident + 1
        markers.append(
            marker_t(
                header=_header(ns, types),
                ns=namespace,
                id=ident,
                type=kind,
                action=marker_t.ADD,
                pose=_pose(at[0], at[1], 0.0, types),
                scale=vector_t(x=scale[0], y=scale[1], z=scale[2]),
                color=color_t(r=color[0], g=color[1], b=color[2], a=color[3]),
                lifetime=duration(sec=0, nanosec=0),
                frame_locked=False,
                points=[point_t(x=float(x), y=float(y), z=0.0) for x, y in points],
                colors=[],
                texture_resource="",
                texture=texture(header=_header(ns, types), format="", data=np.zeros(0, np.uint8)),
                uv_coordinates=[],
                text=text,
                mesh_resource="",
                mesh_file=mesh(filename="", data=np.zeros(0, np.uint8)),
                mesh_use_embedded_materials=False,
            )
        )

    def ring(vertices: np.ndarray) -> np.ndarray:
        return np.vstack([vertices, vertices[:1]])

    xmin, ymin, xmax, ymax = bounds
    add("bounds", marker_t.LINE_STRIP, ring(np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])))
    # the figures' colours (bearnav_cli.palette), so that a bag and a figure of one run read alike
    for namespace, polygons, color in (
        ("obstacles", sim.map.raw_obstacles, rgba(ROLE_COLORS["raw obstacle"])),
        ("inflated", sim.map.obstacles, rgba(ROLE_COLORS["inflated obstacle"], 0.8)),
    ):
        for polygon in polygons:
            for vertices in (polygon.exterior, *polygon.holes):
                add(namespace, marker_t.LINE_STRIP, ring(vertices), color)
    offsets = sim.cell_vertex_offsets
    for c, status in enumerate(sim.cell_status):
        vertices = sim.cell_vertices[offsets[c] : offsets[c + 1]]
        add("cells", marker_t.LINE_STRIP, ring(vertices), STATUS_RGBA[CellStatus(int(status))], (0.5 * width, 0, 0))
    tag = 0.02 * size
    for ident, (x, y) in zip(sim.map.landmark_ids, sim.map.landmarks, strict=True):
        add("tags", marker_t.CUBE, color=rgba(ROLE_COLORS["landmark"]), scale=(tag, tag, tag), at=(x, y))
        add(
            "tag_ids",
            marker_t.TEXT_VIEW_FACING,
            color=rgba(ROLE_COLORS["text"]),
            scale=(0, 0, 1.5 * tag),
            at=(x, y + 1.2 * tag),
            text=str(ident),
        )
    child = np.flatnonzero(sim.parent >= 0)
    edges = np.stack([sim.nodes[child], sim.nodes[sim.parent[child]]], axis=1).reshape(-1, 2)
    add("tree", marker_t.LINE_LIST, edges, rgba(ROLE_COLORS["background tree"], 0.7), (0.5 * width, 0, 0))
    add(
        "goal",
        marker_t.SPHERE,
        color=rgba(ROLE_COLORS["goal"]),
        scale=(2 * tag, 2 * tag, 2 * tag),
        at=tuple(sim.map.goal),
    )
    for r, outcome in enumerate(sim.outcome):
        add("runs", marker_t.LINE_STRIP, sim.trajectory(r), OUTCOME_RGBA.get(int(outcome), (0, 0, 0, 1)))
    return markers


def _put(built: Path, path: Path, staging: Path) -> None:
    """Rename ``built`` (a file or a bag folder) to ``path``, replacing what is there."""
    if built.is_dir() and path.is_dir() and any(path.iterdir()):
        old = staging / "replaced"  # os.replace cannot replace a folder that is not empty
        os.replace(path, old)
        try:
            os.replace(built, path)
        except BaseException:
            os.replace(old, path)
            raise
    else:
        os.replace(built, path)


def write(
    path: str | os.PathLike, sim: Simulation, *, t0_ns: int = 0, option: str | None = "--bag", force: bool = False
) -> dict[str, int]:
    """Write ``sim`` as a ROS 2 bag (module docstring: topics, types, times); return topic -> messages.

    Parameters
    ----------
    path : path-like
        ``NAME.mcap`` (one MCAP file) or ``NAME`` (a ROS 2 bag folder); checked by :func:`check_path`.
    sim : Simulation
        With recorded trajectories (without them the bag holds the markers and empty paths).
    t0_ns : int
        Stamp of the first point and of the markers (ns since the epoch of ROS time).
    option : str, optional
        The option named in errors.
    force : bool, default False
        Replace a ``.mcap`` file bearnav did not write (:func:`check_path`).

    Raises
    ------
    OutputPathError, InvalidParamsError
        A refused path, or rosbags missing.
    """
    path = _checked_path(path, option, force)
    ros = _rosbags(option)
    store = ros["typestore"]
    types = store.types
    if len(sim.trajectory_coords) == 0 and len(sim.outcome):
        log.warning("%s: the simulation recorded no trajectories: the bag has no poses", path)
    stamps = stamps_ns(sim, t0_ns)
    offsets = sim.trajectory_offsets
    heading = sim.trajectory_heading
    coords = sim.trajectory_coords
    serialize = store.serialize_cdr
    pose_t, path_t = types["geometry_msgs/msg/PoseStamped"], types["nav_msgs/msg/Path"]
    counts = dict.fromkeys(TOPICS, 0)
    with artifacts.staging_folder(path) as staging:
        name = path.stem if path.suffix == ".mcap" else path.name
        folder = staging / name
        writer = ros["Writer"](folder, version=9, storage_plugin=ros["mcap"])
        writer.set_compression(*ros["zstd"])
        with writer:
            writer.set_custom_data("bearnav.map", sim.map.name)
            connection = {}
            for topic, msgtype in TOPICS.items():
                qos = ros["latched" if topic == "/bearnav/markers" else "volatile"]
                connection[topic] = writer.add_connection(topic, msgtype, typestore=store, offered_qos_profiles=[qos])
            array = types["visualization_msgs/msg/MarkerArray"](markers=_markers(sim, t0_ns, types))
            writer.write(connection["/bearnav/markers"], t0_ns, serialize(array, array.__msgtype__))
            counts["/bearnav/markers"] += 1
            for r in range(len(sim.outcome)):
                begin, end = int(offsets[r]), int(offsets[r + 1])
                poses = [
                    pose_t(header=_header(int(stamps[p]), types), pose=_pose(*coords[p], heading[p], types))
                    for p in range(begin, end)
                ]
                start = int(stamps[begin]) if end > begin else t0_ns
                message = path_t(header=_header(start, types), poses=poses)
                writer.write(connection["/bearnav/path"], start, serialize(message, message.__msgtype__))
                counts["/bearnav/path"] += 1
                for p, pose in zip(range(begin, end), poses, strict=True):
                    writer.write(connection["/bearnav/pose"], int(stamps[p]), serialize(pose, pose.__msgtype__))
                counts["/bearnav/pose"] += end - begin
        built = folder / f"{name}.mcap" if path.suffix == ".mcap" else folder
        _put(built, path, staging)
    log.info("wrote %s: %s", path, ", ".join(f"{n} on {t}" for t, n in counts.items()))
    return counts
