"""Reading the files a command is given: map YAMLs (bearnav maps, ROS map_server grids and their images),
sweep YAMLs, and the ``X,Y`` of the map options.

:func:`read_map_source` is public: the benchmarks and tests read maps with it, as ``bearnav plan`` does.
"""

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, List, Optional

from bearnav_cli.errors import BearnavError, InvalidMapError

if TYPE_CHECKING:
    from bearnav_cli.stages.map_ import GridSource, MapSource

__all__ = ["is_bare_grid", "parse_xy", "read_bytes", "read_grid", "read_map_source", "read_yaml"]


def read_bytes(path: Path, field: str | None = None, what: str = "file") -> bytes:
    """An input file's bytes (``artifacts.read_input``: a regular file, within the memory budget); a problem is an
    :class:`InvalidMapError` naming the file (and ``field``, the map key that named it)."""
    from bearnav_cli import artifacts

    return artifacts.read_input(path, InvalidMapError, what, field)


def read_yaml(path: Path) -> tuple[Any, bytes]:
    """A YAML file's document and its bytes (they hash the input); a syntax error names the line."""
    import yaml

    data = read_bytes(path)
    try:
        # libyaml's parser when pyyaml has it (the same documents, about 9× faster), else pyyaml's own
        return yaml.load(data, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)), data
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or "syntax error"
        raise InvalidMapError(f"not valid YAML ({problem}{where})", file=str(path)) from exc


def read_grid(grid_yaml: Path, owner: str, field: str) -> "tuple[GridSource, list[bytes]]":
    """Read a ROS map_server YAML and its image: the grid and the bytes that hash it (``owner`` and ``field``:
    the file and the key or option that named it, for the error)."""
    from bearnav_cli.stages.map_ import GridSource

    if not grid_yaml.is_file():
        raise InvalidMapError(f"occupancy file {str(grid_yaml)!r} does not exist", file=owner, field=field)
    meta, meta_bytes = read_yaml(grid_yaml)
    if not isinstance(meta, dict) or not isinstance(meta.get("image"), str):
        raise InvalidMapError("not a map_server YAML (needs an 'image' key)", file=str(grid_yaml), field="image")
    image_path = (grid_yaml.parent / meta["image"]).resolve()
    image = read_bytes(image_path, field="image", what="image")
    return GridSource(meta, image, str(grid_yaml), str(image_path)), [meta_bytes, image]


def is_bare_grid(path: Path) -> bool:
    """Whether ``path`` is a bare ROS map_server YAML (an ``image:`` key, no bearnav map around it)."""
    try:
        spec, _ = read_yaml(path)
    except BearnavError:
        return False
    return isinstance(spec, dict) and "image" in spec


def read_map_source(
    path: Path,
    goal: Optional[List[float]] = None,
    landmarks: Optional[List[str]] = None,
    starts: Optional[List[str]] = None,
    robot_radius: Optional[float] = None,
    lookahead: Optional[float] = None,
    robot: Optional[dict] = None,
) -> "MapSource":
    """Read a bearnav map YAML (or a bare ROS map_server YAML plus options) into a MapSource.

    ``lookahead`` (``--lookahead``, any map) overrides the map's ``robot.lookahead``, and ``robot``
    (``plan --slip`` ...: ``{key: value}`` of the ``robot:`` section) the other keys it names; like the
    bare grid's options they are part of the input hash, so another value reruns the map stage.
    """
    import hashlib

    from bearnav_cli.stages.map_ import MapSource

    spec, data = read_yaml(path)
    if not isinstance(spec, dict):
        raise InvalidMapError("expected a mapping at the top level", file=str(path))
    if isinstance(spec.get("manifest"), dict) and "schema" in spec["manifest"]:
        raise InvalidMapError(
            f"is an artifact ({spec['manifest']['schema']}), not a map YAML; plan from it with `bearnav plan {path}`",
            file=str(path),
        )
    blobs = [data]
    grid = None
    robot_given = {**(robot or {}), **({"lookahead": lookahead} if lookahead is not None else {})}
    if "image" not in spec:
        given = [
            name
            for name, value in (
                ("--goal", goal),
                ("--landmark", landmarks),
                ("--start", starts),
                ("--robot-radius", robot_radius),
            )
            if value not in (None, [])
        ]
        if given:
            raise BearnavError(
                f"{given[0]}: only for a bare map_server YAML; {path} is a bearnav map, set it there (docs/maps.md)"
            )
    if "image" in spec:  # a bare map_server YAML: the rest comes from options
        grid, extra = read_grid(path, str(path), "image")
        blobs = extra
        spec = {"name": path.stem}
        if goal is None:
            raise InvalidMapError("a bare occupancy grid needs --goal X,Y", file=str(path), field="goal")
        spec["goal"] = list(goal)
        spec["landmarks"] = [parse_xy(text, "--landmark") for text in landmarks or []]
        spec["starts"] = [parse_xy(text, "--start") for text in starts or []]
        if robot_radius is not None:
            spec["robot_radius"] = robot_radius
        if robot_given:
            spec["robot"] = dict(robot_given)
        # the options are part of the input: other options must make the map stage rerun
        blobs.append(json.dumps(spec, sort_keys=True).encode())
    else:
        spec.setdefault("name", path.stem)
        if robot_given and isinstance(spec.get("robot") or {}, dict):  # else the map stage names it
            spec["robot"] = {**(spec.get("robot") or {}), **robot_given}
            blobs.append(
                json.dumps(
                    {"--" + key.replace("_", "-"): value for key, value in robot_given.items()}, sort_keys=True
                ).encode()
            )
        if "occupancy" in spec:
            if not isinstance(spec["occupancy"], str):
                raise InvalidMapError("expected a file name", file=str(path), field="occupancy")
            grid, extra = read_grid(path.parent / spec["occupancy"], str(path), "occupancy")
            blobs += extra
    digest = hashlib.sha256()
    for blob in blobs:
        digest.update(hashlib.sha256(blob).digest())
    return MapSource(spec=spec, file=str(path), sha256=digest.hexdigest(), grid=grid)


def parse_xy(text: str, option: str) -> list[float]:
    """``X,Y`` of a map option (``--goal 1,2``) as two floats; anything else names the option."""
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise BearnavError(f"{option}: expected X,Y, got {text!r}") from None
    return [x, y]
