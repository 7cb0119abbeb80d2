"""Never replace what bearnav did not write: which command wrote a file or a bag, told by its content.

:func:`written_by` reads a manifest, the marker line of a ``tags`` map or the custom data of a
bag; :func:`check_overwrite` refuses to replace anything else without ``--force``, and
:func:`check_plan_folder` a plan folder of another map.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bearnav_cli.artifacts.reading import ZIP_MAGIC
from bearnav_cli.errors import OutputPathError

__all__ = ["BAG_MARKER", "check_overwrite", "check_plan_folder", "Origin", "TAGS_MARKER", "written_by"]


#: The first line of every map YAML ``bearnav tags`` writes (a YAML comment): how a later run tells
#: its own output from a map someone wrote by hand.
TAGS_MARKER = "# bearnav tags:"
#: The custom-data key every bag ``simulate --bag`` writes carries (``metadata.yaml``, or inside the MCAP file).
BAG_MARKER = "bearnav.map"
#: How much of the end of an MCAP file is searched for :data:`BAG_MARKER`: rosbags writes the
#: metadata record (uncompressed) after the data, at close.
_MCAP_TAIL = 1 << 20


@dataclass(frozen=True)
class Origin:
    """Which bearnav command wrote an output (:func:`written_by`).

    Attributes
    ----------
    command : str
        A stage (``"map"`` ... ``"synthesize"``, ``"simulate"``, also for ``sim.json``), ``"tags"``
        (a map YAML) or ``"bag"`` (a ROS 2 bag, file or folder).
    map_name : str or None
        The name of the map it was made from, where the file records it (map.json and the npz artifacts).
    """

    command: str
    map_name: str | None = None


def _npz_origin(path: Path) -> Origin | None:
    # only the manifest and map members are read: a plan's arrays stay on disk
    with np.load(path, allow_pickle=False) as npz:
        if "manifest" not in npz.files:
            return None
        manifest = json.loads(str(npz["manifest"]))
        document = json.loads(str(npz["map"])) if "map" in npz.files else {}
    if not isinstance(manifest, dict) or not isinstance(manifest.get("stage"), str):
        return None
    name = document.get("name") if isinstance(document, dict) else None
    return Origin(manifest["stage"], name if isinstance(name, str) else None)


def _json_origin(path: Path) -> Origin | None:
    document = json.loads(path.read_bytes().decode("utf-8"))
    manifest = document.get("manifest") if isinstance(document, dict) else None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("stage"), str):
        return None
    name = document.get("name")  # map.json's; sim.json does not name its map
    return Origin(manifest["stage"], name if isinstance(name, str) and manifest["stage"] == "map" else None)


def _bag_folder_origin(path: Path) -> Origin | None:
    metadata = path / "metadata.yaml"
    if not metadata.is_file() or BAG_MARKER not in metadata.read_text(errors="replace"):
        return None
    # what bearnav writes there: metadata.yaml and the MCAP file; anything else is someone's
    if any(
        child.name != "metadata.yaml" and (child.suffix != ".mcap" or not child.is_file()) for child in path.iterdir()
    ):
        return None
    return Origin("bag")


def _mcap_origin(path: Path) -> Origin | None:
    with open(path, "rb") as handle:
        handle.seek(max(0, path.stat().st_size - _MCAP_TAIL))
        return Origin("bag") if BAG_MARKER.encode() in handle.read() else None


def written_by(path: str | os.PathLike) -> Origin | None:
    """Which bearnav command wrote ``path``, or None if bearnav did not (or it cannot tell).

    Told by content, never by name alone: an npz or JSON artifact by its manifest's ``stage``
    (``sim.json`` too), a map YAML by :data:`TAGS_MARKER` on its first line, a ROS 2 bag by
    :data:`BAG_MARKER` in its metadata (a bag folder must hold nothing else than ``metadata.yaml``
    and MCAP files). A file too damaged to show its manifest gives None.

    Parameters
    ----------
    path : str or os.PathLike
        An existing file or folder.

    Returns
    -------
    Origin or None
        The command (and the map's name where the file records it).
    """
    path = Path(path)
    try:
        if path.is_symlink():  # replacing a link replaces the link, not what it points to: never bearnav's
            return None
        if path.is_dir():
            return _bag_folder_origin(path)
        if not path.is_file():
            return None
        suffix = path.suffix.lower()
        if suffix in (".yaml", ".yml"):
            with open(path, "rb") as handle:
                first = handle.readline(4096).decode("utf-8", errors="replace")
            return Origin("tags") if first.startswith(TAGS_MARKER) else None
        if suffix == ".mcap":
            return _mcap_origin(path)
        with open(path, "rb") as handle:
            head = handle.read(4)
        if head in ZIP_MAGIC:
            return _npz_origin(path)
        if suffix == ".json":
            return _json_origin(path)
    except Exception:  # noqa: BLE001 - a damaged or unreadable file is not known to be bearnav's
        return None
    return None


def check_overwrite(
    path: str | os.PathLike, command: str, *, force: bool = False, option: str | None = "-o/--out"
) -> None:
    """Refuse to replace ``path`` unless it is missing, an output of ``command`` (:func:`written_by`), or ``force``.

    Parameters
    ----------
    path : str or os.PathLike
        An output the run will write (or replace).
    command : str
        The command about to write it, as :class:`Origin` names it (``"simulate"``, ``"tags"``).
    force : bool, default False
        Replace it whoever wrote it (the user's ``--force``).
    option : str or None, default "-o/--out"
        The option that gave ``path``, named in the error.

    Raises
    ------
    OutputPathError
        ``path`` exists and bearnav's ``command`` did not write it.
    """
    path = Path(path)
    if force or not os.path.lexists(path):
        return
    origin = written_by(path)
    if origin is None:
        raise OutputPathError(
            "exists and was not written by bearnav; give another name, or --force to replace it",
            file=str(path),
            option=option,
        )
    if origin.command != command:
        raise OutputPathError(
            f"is an output of bearnav {origin.command}, not {command}; give another name, or --force to replace it",
            file=str(path),
            option=option,
        )


def check_plan_folder(
    folder: str | os.PathLike,
    names: tuple[str, ...],
    map_name: str,
    *,
    force: bool = False,
    option: str | None = "-o/--out",
) -> None:
    """Refuse a plan folder that holds the artifacts of another map (a plan folder belongs to one map).

    The same map planned again (other parameters, an edited YAML, another file with the same
    ``name:``) is the normal case and passes; so does a folder without artifacts.

    Parameters
    ----------
    folder : str or os.PathLike
        The plan folder.
    names : tuple of str
        The artifact files of a plan (``map.json``, ``tree.npz`` ...), which record their map's name.
    map_name : str
        The name of the map about to be planned there.
    force : bool, default False
        Plan there anyway (its artifacts are replaced).
    option : str or None, default "-o/--out"
        The option that gave ``folder``, named in the error.

    Raises
    ------
    OutputPathError
        The folder holds another map's artifacts, naming the folder and that map.
    """
    if force:
        return
    for name in names:
        origin = written_by(Path(folder) / name) if os.path.lexists(Path(folder) / name) else None
        if origin is not None and origin.map_name is not None and origin.map_name != map_name:
            raise OutputPathError(
                f"holds the plan of the map {origin.map_name!r} ({name}), not of {map_name!r}; "
                "give another folder, or --force to replace it",
                file=str(folder),
                option=option,
            )
