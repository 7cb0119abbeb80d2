"""Reading an artifact file with numpy and the standard library only, and the robot's one loader of ``plan.npz``.

The checks here are the ones :func:`bearnav_cli.artifacts.load` makes (it calls these functions),
so that the robot and ``bearnav inspect`` refuse the same files (DESIGN §3.1, §6):

- :func:`read_input`, :func:`parse_npz`: the file, its zip, every member's deflate stream and
  ``.npy`` header, the manifest entry; a damaged file raises :class:`ArtifactError` naming it
  (and the entry, once known), never a raw ``zlib.error``, ``EOFError`` or ``BadZipFile``;
- :func:`check_manifest_fields`: the manifest's fields (:data:`MANIFEST_FIELDS`) and its stage;
- :func:`check_entries`, :func:`shape_problem`: every declared entry there with its dtype kind,
  its number of dimensions and shapes that agree, nothing else;
- :func:`content_hash`: the hash over the data entries, recomputed and compared;
- :func:`load_plan`: all of the above for a ``plan.npz``, then the embedded map
  (:func:`embedded_map`) and the plan's form and meaning (:mod:`bearnav_cli.runtime.invariants`).
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import stat
import zipfile
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np

from bearnav_cli.errors import ArtifactError
from bearnav_cli.runtime import invariants, schema
from bearnav_cli.runtime.robot import robot_problem

__all__ = [
    "canonical_json",
    "check_entries",
    "check_manifest_fields",
    "content_hash",
    "EmbeddedMap",
    "embedded_map",
    "human_bytes",
    "load_plan",
    "LoadedPlan",
    "MANIFEST_FIELDS",
    "map_text",
    "memory_budget",
    "parse_npz",
    "plan_view",
    "read_input",
    "shape_problem",
    "UNHASHED_MAP_FIELDS",
]

#: Manifest fields (DESIGN §3.1): name -> (accepted JSON types, required).
MANIFEST_FIELDS: dict[str, tuple[tuple[type, ...], bool]] = {
    "schema": ((str,), True),
    "stage": ((str,), True),
    "stage_version": ((int,), True),
    "params": ((dict,), True),
    "input": ((dict,), True),
    "content_sha256": ((str,), True),
    "key": ((str,), True),
    "software": ((dict,), False),
    "summary": ((str,), False),
    "elapsed_s": ((int, float), False),
    "stats": ((dict,), False),
}

#: Fields of the map document that stay out of every content hash: ``source`` is provenance,
#: ``params`` the per-stage overrides, which reach each stage's cache key through its resolved
#: parameters instead (a stage reruns only when what it computes from changes).
UNHASHED_MAP_FIELDS = ("source", "params")

_NPY_MAGIC = b"\x93NUMPY"
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


# --------------------------------------------------------------------------- hashing


def canonical_json(value: Any) -> str:
    """Deterministic JSON text: sorted keys, no spaces, plain floats."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=True)


def content_hash(entries: dict[str, Any]) -> str:
    """SHA-256 over data entries in sorted key order (name, dtype, shape and bytes of each), 64 hex digits.

    The map (``map.json``'s document, or the ``map`` entry every later artifact embeds) is hashed
    without :data:`UNHASHED_MAP_FIELDS`, as canonical JSON. Texts are hashed as UTF-8, arrays
    with their dtype string (``<f8``), shape and C-order bytes.
    """
    if "map" in entries:
        value = entries["map"]
        entries = {**entries, "map": (_hashed_map_text if isinstance(value, str) else _map_to_hash)(value)}
    digest = hashlib.sha256()
    for key in sorted(entries):
        value = entries[key]
        if isinstance(value, str):
            digest.update(f"{key}|str|".encode())
            digest.update(value.encode())
        else:
            array = np.ascontiguousarray(value)
            digest.update(f"{key}|{array.dtype.str}|{array.shape}|".encode())
            digest.update(array.tobytes())
    return digest.hexdigest()


def _map_to_hash(value: Any) -> Any:
    """The map entry :func:`content_hash` hashes: its JSON object as canonical JSON without
    :data:`UNHASHED_MAP_FIELDS`; anything else as it is (a damaged entry: its loader names the problem)."""
    try:
        document = json.loads(value)
    except (TypeError, ValueError):
        return value
    if not isinstance(document, dict):
        return value
    for name in UNHASHED_MAP_FIELDS:
        document.pop(name, None)
    return canonical_json(document)


#: :func:`_map_to_hash` of the map texts met last (text -> what is hashed), made once per text: ``bearnav plan``
#: hashes the same embedded map in each of its artifacts, and a loaded artifact's once more.
_HASHED_MAP_TEXTS: dict[str, Any] = {}
_HASHED_MAP_TEXTS_KEPT = 4


def _hashed_map_text(text: str) -> Any:
    """:func:`_map_to_hash` of ``text``, remembered (:data:`_HASHED_MAP_TEXTS`)."""
    found = _HASHED_MAP_TEXTS.get(text)
    if found is None:
        found = _map_to_hash(text)
        _remember_hashed_map_text(text, found)
    return found


def _remember_hashed_map_text(text: str, hashed: Any) -> None:
    while len(_HASHED_MAP_TEXTS) >= _HASHED_MAP_TEXTS_KEPT:  # the oldest goes first (dicts keep their order)
        del _HASHED_MAP_TEXTS[next(iter(_HASHED_MAP_TEXTS))]
    _HASHED_MAP_TEXTS[text] = hashed


def map_text(document: dict[str, Any]) -> str:
    """``canonical_json(document)`` of a map document (str keys, JSON values), and what :func:`content_hash`
    hashes for that text, made from the same document and remembered: hashing the text later does not parse
    it back (half a millisecond to two of a ``map.json`` read or a stage's output written).
    """
    if not all(isinstance(key, str) for key in document):  # json.dumps would write other keys as strings
        return canonical_json(document)
    # canonical JSON of an object is "{" + its sorted "key":value pairs joined by "," + "}": each value's text
    # is made once, for both texts
    pieces = {key: f"{canonical_json(key)}:{canonical_json(value)}" for key, value in sorted(document.items())}
    text = "{" + ",".join(pieces.values()) + "}"
    if text not in _HASHED_MAP_TEXTS:
        hashed = "{" + ",".join(piece for key, piece in pieces.items() if key not in UNHASHED_MAP_FIELDS) + "}"
        _remember_hashed_map_text(text, hashed)
    return text


# --------------------------------------------------------------------------- reading


def memory_budget() -> int:
    """Bytes a single request may use: half of this machine's physical memory (``os.sysconf``)."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")) // 2
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 4 << 30


def human_bytes(count: float) -> str:
    """``"1.5 GB"``."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(count) < 1000 or unit == "PB":
            return f"{count:.3g} {unit}" if unit != "B" else f"{int(count)} B"
        count /= 1000
    return f"{count:.3g} EB"  # pragma: no cover


def read_input(
    path: str | os.PathLike,
    error: Callable[..., Exception] = ArtifactError,
    what: str = "file",
    field: str | None = None,
) -> bytes:
    """The bytes of an input file: a regular file no larger than :func:`memory_budget`, or one clear error.

    A device (``/dev/zero``), a FIFO or a socket is refused from its ``stat`` without opening it
    (reading one never ends, or blocks for ever), and so is a file larger than a run may hold.

    Parameters
    ----------
    path : path-like
        The file.
    error : callable
        The error class raised, called as ``error(message, file=path, field=field)``
        (:class:`~bearnav_cli.errors.ArtifactError` or :class:`~bearnav_cli.errors.InvalidMapError`).
    what : str
        What the file is, for the message (``"file"``, ``"image"``).
    field : str, optional
        The field that named the file (a map's ``image``), for the message.
    """
    path = Path(path)
    where = {"file": str(path), "field": field}
    try:
        info = path.stat()
    except FileNotFoundError:
        raise error(f"no such {what}", **where) from None
    except OSError as exc:
        raise error(f"cannot read the {what} ({exc.strerror or exc})", **where) from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f"is a folder, not a{'n' if what[0] in 'aeiou' else ''} {what}", **where)
    if not stat.S_ISREG(info.st_mode):
        raise error("not a regular file (a device, FIFO or socket): bearnav reads only files", **where)
    budget = memory_budget()
    if info.st_size > budget:
        raise error(f"{human_bytes(info.st_size)}, more than the {human_bytes(budget)} a run may use", **where)
    try:
        return path.read_bytes()
    except PermissionError:
        raise error(f"cannot read the {what} (permission denied)", **where) from None
    except OSError as exc:
        raise error(f"cannot read the {what} ({exc.strerror or exc})", **where) from None


def parse_npz(data: bytes, file: str, budget: int | None = None) -> tuple[dict, dict[str, Any]]:
    """The manifest and data entries of an npz artifact's bytes (``allow_pickle=False``).

    Parameters
    ----------
    data : bytes
        The file's content.
    file : str
        Its name, for the errors.
    budget : int, optional
        Bytes the arrays may declare in all (default :func:`memory_budget`).

    Returns
    -------
    manifest : dict
        The ``manifest`` entry's JSON object.
    entries : dict
        Every other entry: 0-d text arrays as ``str``, the rest as arrays.

    Raises
    ------
    ArtifactError
        Not a zip, a damaged zip or member (deflate stream, CRC, ``.npy`` header), an object
        array, a member that is not ``.npy``, more data than ``budget``, no manifest or one
        that is not a JSON object; naming ``file`` and the entry when one is to blame.
    """
    budget = memory_budget() if budget is None else budget
    if data.startswith(_NPY_MAGIC):
        raise ArtifactError("is a single .npy array, not an .npz archive", file=file)
    if not data.startswith(_ZIP_MAGIC):
        raise ArtifactError("not an npz archive (not a zip file)", file=file)
    buffer = io.BytesIO(data)
    try:
        with zipfile.ZipFile(buffer) as archive:
            infos = archive.infolist()
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, ValueError, EOFError) as exc:
        raise ArtifactError(f"damaged zip archive ({exc})", file=file) from None
    declared = sum(info.file_size for info in infos)
    if declared > budget:
        raise ArtifactError(
            f"declares {human_bytes(declared)} of data, more than the {human_bytes(budget)} a load may use", file=file
        )
    for info in infos:
        if not info.filename.endswith(".npy"):
            raise ArtifactError(f"unexpected member {info.filename!r} (an npz holds .npy arrays)", file=file)
    arrays: dict[str, np.ndarray] = {}
    key = None
    try:
        with np.load(buffer, allow_pickle=False) as npz:
            for key in npz.files:
                arrays[key] = npz[key]
    except MemoryError:
        raise ArtifactError("too large to load", file=file, field=key) from None
    except Exception as exc:  # noqa: BLE001 - zlib, zipfile, EOF, numpy's format errors: the file is damaged
        what = f"damaged entry ({type(exc).__name__}: {exc})" if key else f"damaged npz ({type(exc).__name__}: {exc})"
        raise ArtifactError(what, file=file, field=key) from None
    raw = arrays.pop("manifest", None)
    if raw is None:
        raise ArtifactError("no manifest entry (not a bearnav artifact)", file=file)
    if raw.dtype.kind != "U" or raw.ndim != 0:
        raise ArtifactError(
            f"expected a 0-d JSON text, got a {raw.ndim}-d {raw.dtype} array", file=file, field="manifest"
        )
    try:
        manifest = json.loads(str(raw))
    except json.JSONDecodeError as exc:
        raise ArtifactError(f"not valid JSON ({exc})", file=file, field="manifest") from None
    if not isinstance(manifest, dict):
        raise ArtifactError(f"expected a JSON object, got {type(manifest).__name__}", file=file, field="manifest")
    entries = {k: (str(v) if v.dtype.kind == "U" and v.ndim == 0 else v) for k, v in arrays.items()}
    return manifest, entries


def check_manifest_fields(manifest: dict, file: str, stage: str) -> None:
    """Every field of :data:`MANIFEST_FIELDS` with its JSON type, ``stage`` the one that writes the schema.

    Parameters
    ----------
    manifest : dict
        The manifest, its ``schema`` already known to be current.
    file : str
        The file, for the errors.
    stage : str
        The stage that writes this schema (``schema.STAGES[kind]``).

    Raises
    ------
    ArtifactError
        Naming ``manifest.FIELD``.
    """
    for name, (types, required) in MANIFEST_FIELDS.items():
        if name not in manifest:
            if required:
                raise ArtifactError("missing", file=file, field=f"manifest.{name}")
            continue
        value = manifest[name]
        if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
            wanted = " or ".join("an object" if t is dict else t.__name__ for t in types)
            raise ArtifactError(f"expected {wanted}, got {type(value).__name__}", file=file, field=f"manifest.{name}")
    if manifest["stage"] != stage:
        raise ArtifactError(
            f"is {manifest['stage']!r}, but {manifest['schema']} is written by {stage!r}",
            file=file,
            field="manifest.stage",
        )
    if not isinstance(manifest["input"].get("content_sha256"), str):
        raise ArtifactError("expected a hash text", file=file, field="manifest.input.content_sha256")
    if not isinstance(manifest["input"].get("path"), (str, type(None))):
        raise ArtifactError("expected a path or null", file=file, field="manifest.input.path")


def shape_problem(kind: str, entries: dict[str, Any]) -> tuple[str, str] | None:
    """The first entry whose shape disagrees with the others' (``schema.ENTRIES[kind]``), as ``(field, text)``.

    Each dimension name (N, C, L ...) takes its length from the first declared entry that has it
    alone on an axis; every entry must then have its resolved shape. Entries must be there with
    their number of dimensions (:func:`check_entries`).
    """
    declared = schema.ENTRIES[kind]
    dims: dict[str, int] = {}
    for name, entry in declared.items():
        if entry.dtype == "str":
            continue
        shape = np.shape(entries[name])
        for item, length in zip(entry.shape, shape, strict=True):
            if isinstance(item, str) and item.isalpha() and item not in dims:
                dims[item] = length
        want = entry.resolve(dims)
        if shape != want:
            return name, f"expected shape {schema.shape_text(entry.shape)} = {want}, got {shape}"
    return None


def check_entries(kind: str, entries: dict[str, Any], file: str) -> None:
    """Every entry of ``schema.ENTRIES[kind]`` there, with its dtype kind and dimensions, and no other.

    Parameters
    ----------
    kind : str
        The artifact kind (``"plan"``), a key of ``schema.ENTRIES``.
    entries : dict
        The data entries (:func:`parse_npz`): 0-d texts as ``str``, the rest arrays.
    file : str
        The file, for the errors.

    Raises
    ------
    ArtifactError
        Naming ``file`` and the entry: missing, a text where an array belongs (or the reverse),
        the wrong dtype kind or number of dimensions, unexpected.
    """
    declared = schema.ENTRIES[kind]
    for key, entry in declared.items():
        dtype_kind, ndim = entry.kind, entry.ndim
        if key not in entries:
            raise ArtifactError("missing entry", file=file, field=key)
        value = entries[key]
        if dtype_kind == "U":
            if not isinstance(value, str):
                raise ArtifactError("expected a JSON text", file=file, field=key)
        elif isinstance(value, str):
            raise ArtifactError(f"expected a {ndim}-d {dtype_kind} array, got a text", file=file, field=key)
        elif value.dtype.kind != dtype_kind or value.ndim != ndim:
            raise ArtifactError(
                f"expected a {ndim}-d {dtype_kind} array, got a {value.ndim}-d {value.dtype} one", file=file, field=key
            )
    extra = sorted(set(entries) - set(declared))
    if extra:
        raise ArtifactError(f"unexpected entry (not part of {schema.SCHEMAS[kind]})", file=file, field=extra[0])


# --------------------------------------------------------------------------- the embedded map


@dataclass(frozen=True, eq=False)
class EmbeddedMap:
    """What the robot reads of the map a ``plan.npz`` embeds (its ``map`` entry).

    Attributes
    ----------
    document : dict
        The parsed JSON (the robot section, ``robot``, is read from it).
    bounds : ndarray of float64, shape (4,)
        ``[xmin, ymin, xmax, ymax]`` (map units), finite, ``xmin < xmax`` and ``ymin < ymax``.
    goal : ndarray of float64, shape (2,)
        The goal (map units).
    landmarks : ndarray of float64, shape (L, 2)
        Landmark positions (map units).
    robot_radius : float
        ρ (map units), finite, zero or positive.
    obstacles, raw_obstacles : list of tuple of ndarray
        Each obstacle's rings (exterior, then holes), each of shape (m, 2) (map units): inflated
        and raw.
    """

    document: dict
    bounds: np.ndarray
    goal: np.ndarray
    landmarks: np.ndarray
    robot_radius: float
    obstacles: list
    raw_obstacles: list

    @property
    def diagonal(self) -> float:
        """D, the length of the bounds' diagonal (map units)."""
        return math.hypot(self.bounds[2] - self.bounds[0], self.bounds[3] - self.bounds[1])

    @property
    def tol(self) -> float:
        """``1e-9·D`` (map units), the geometric tolerance (ALGORITHMS §0)."""
        return 1e-9 * self.diagonal


def embedded_map(document: Any, file: str | None = None) -> EmbeddedMap:
    """Read the embedded map's JSON (text or parsed) as the robot needs it.

    Raises
    ------
    ArtifactError
        ``map`` (not JSON, not an object, a field missing or malformed) or ``map.bounds``.
    """
    try:
        if isinstance(document, str):
            document = json.loads(document)
        if not isinstance(document, dict):
            raise TypeError(f"expected a JSON object, got {type(document).__name__}")
        bounds = np.asarray(document["bounds"], float).reshape(4)
        goal = np.asarray(document["goal"], float).reshape(2)
        landmarks = np.asarray([lm["position"] for lm in document["landmarks"]], float).reshape(-1, 2)
        radius = float(document.get("robot_radius", 0.0))
        rings = [
            [
                (
                    np.asarray(o["exterior"], float).reshape(-1, 2),
                    *(np.asarray(h, float).reshape(-1, 2) for h in o.get("holes", ())),
                )
                for o in document[key]
            ]
            for key in ("obstacles", "raw_obstacles")
        ]
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ArtifactError(f"malformed embedded map ({type(exc).__name__}: {exc})", file=file, field="map") from None
    if not (np.all(np.isfinite(bounds)) and bounds[0] < bounds[2] and bounds[1] < bounds[3]):
        raise ArtifactError("needs finite xmin < xmax and ymin < ymax", file=file, field="map.bounds")
    if not (math.isfinite(radius) and radius >= 0):
        raise ArtifactError(f"must be finite, zero or positive, got {radius:g}", file=file, field="map.robot_radius")
    robot = robot_problem(document.get("robot"))
    if robot is not None and robot[0] == "" and not isinstance(document.get("robot"), dict):
        raise ArtifactError(f"malformed embedded map (robot: {robot[1]})", file=file, field="map")
    if robot is not None:
        raise ArtifactError(robot[1], file=file, field=f"map.robot.{robot[0]}".rstrip("."))
    if not (np.all(np.isfinite(goal)) and np.all(np.isfinite(landmarks))):
        raise ArtifactError(
            "contains NaN or infinity",
            file=file,
            field="map.goal" if not np.all(np.isfinite(goal)) else "map.landmarks",
        )
    return EmbeddedMap(document, bounds, goal, landmarks, radius, rings[0], rings[1])


# --------------------------------------------------------------------------- the robot's loader


@dataclass(frozen=True, eq=False)
class LoadedPlan:
    """A ``plan.npz`` that passed every check of :func:`load_plan`.

    Attributes
    ----------
    path : Path
        The file.
    manifest : dict
        Its manifest (DESIGN §3.1).
    entries : dict of str to ndarray, str or float
        Every data entry but ``map``, with the dtypes ``schema.ENTRIES["plan"]`` declares (read-only
        arrays; 0-d numbers as ``float``, ``certificate`` as ``str``).
    map : EmbeddedMap
        The embedded map.
    """

    path: Path
    manifest: dict
    entries: dict
    map: EmbeddedMap


def plan_view(entries: dict[str, Any], map_: EmbeddedMap) -> SimpleNamespace:
    """The entries of a plan (every key of ``ENTRIES["plan"]`` but ``map``) with their declared dtypes, as
    attributes, the map as ``map``: what :mod:`~bearnav_cli.runtime.invariants` reads."""
    typed: dict[str, Any] = {}
    for name, entry in schema.ENTRIES["plan"].items():
        if name == "map":
            continue
        value = entries[name]
        if entry.dtype == "str":
            typed[name] = str(value)
        elif entry.ndim == 0:
            typed[name] = float(value)
        else:
            array = np.array(value, dtype=entry.numpy_dtype, copy=True)
            array.setflags(write=False)
            typed[name] = array
    return SimpleNamespace(**typed, map=map_)


def load_plan(path: str | os.PathLike) -> LoadedPlan:
    """Load ``plan.npz`` with every check the CLI's loader makes that numpy can make.

    The file, its zip and members (:func:`parse_npz`); the manifest (its ``schema`` the current
    plan schema, its fields, its stage); the entries (:func:`check_entries`, :func:`shape_problem`);
    the content hash; the embedded map (:func:`embedded_map`); the form and meaning of the cells
    and the controllers (:func:`~bearnav_cli.runtime.invariants.check_cells_form`,
    :data:`~bearnav_cli.runtime.invariants.CELLS_INVARIANTS`, ``check_plan_form``,
    ``PLAN_INVARIANTS``); landmarks equal to the map's; one cell per tree node. Not checked here:
    what needs shapely (the map's polygons are simple, its goal and starts free), which
    ``bearnav inspect`` adds.

    Parameters
    ----------
    path : path-like
        The ``plan.npz`` file.

    Returns
    -------
    LoadedPlan

    Raises
    ------
    ArtifactError
        Naming the file and the field: the one exception of a plan that fails.
    """
    path = Path(path)
    file = str(path)
    manifest, entries = parse_npz(read_input(path), file)
    found, current = manifest.get("schema"), schema.SCHEMAS["plan"]
    if found in schema.RETIRED_PLAN_SCHEMAS:
        raise ArtifactError(
            f"is a {found} plan, which this version no longer reads; re-run "
            f"`bearnav plan MAP.yaml --force` to get {current}",
            file=file,
            field="manifest.schema",
        )
    if found != current:
        what = f"is a {found} artifact" if found in schema.SCHEMAS.values() else f"unknown schema {found!r}"
        raise ArtifactError(f"{what}, expected {current}", file=file, field="manifest.schema")
    check_manifest_fields(manifest, file, schema.STAGES["plan"])
    check_entries("plan", entries, file)
    problem = shape_problem("plan", entries)
    if problem is not None:
        raise ArtifactError(problem[1], file=file, field=problem[0])
    if content_hash(entries) != manifest["content_sha256"]:
        raise ArtifactError("content hash mismatch (file corrupted or edited)", file=file)
    map_ = embedded_map(entries["map"], file)
    try:
        view = plan_view(entries, map_)
        invariants.check_cells_form(view)
        invariants.check_plan_form(view)
        problem = invariants.landmarks_problem(view.landmarks, map_.landmarks)
        if problem is not None:
            raise ArtifactError(problem, field="landmarks")
        if len(view.cell_node) != len(view.nodes):
            raise ArtifactError("every tree node must own exactly one cell", field="cell_node")
        invariants.validate(invariants.CELLS_INVARIANTS, view)
        invariants.validate(invariants.PLAN_INVARIANTS, view)
    except ArtifactError as exc:
        raise exc.located(file) from None
    typed = {name: value for name, value in vars(view).items() if name != "map"}
    return LoadedPlan(path, manifest, typed, map_)
