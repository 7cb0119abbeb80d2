"""Reading and writing every artifact, with manifests and content hashes (DESIGN §3).

This is the only package that touches artifact files. Each file is self-describing: npz files
hold a ``manifest`` entry (0-d JSON string), ``map.json`` a top-level ``"manifest"`` object.
Every name is re-exported here (``from bearnav_cli import artifacts; artifacts.load(path)``);
its modules, each with one job:

- :mod:`~bearnav_cli.artifacts.manifest` — kinds and schemas, data entries, content hashes, cache
  keys and manifests;
- :mod:`~bearnav_cli.artifacts.reading` — **one loader**, :func:`load`: every way a read can fail (a
  missing or unreadable file, a folder, a damaged zip or deflate stream, a ``.npy`` where an
  ``.npz`` belongs, JSON that is not an object, a manifest without its fields, missing or extra
  entries, dtypes, shapes, the content hash) raises :class:`ArtifactError` naming the file and the
  problem; then the artifact's meaning is checked (``datatypes.INVARIANTS``), whatever its hash
  says; :func:`fresh` decides whether an output is kept;
- :mod:`~bearnav_cli.artifacts.writing` — :func:`save`, checked against the same invariants first;
  ``sim.npz`` + ``sim.json`` are committed together;
- :mod:`~bearnav_cli.artifacts.atomic` — **writes** are atomic (temp files in the same folder, then
  ``os.replace``, with SIGINT and SIGTERM held back while the files are renamed). Temp files are
  named ``.NAME.bearnav-PID-MARK-XXXX.tmp``: those of a run that died are removed by the next one;
- :mod:`~bearnav_cli.artifacts.outputs` — **output folders**: :func:`check_output_file` and
  :func:`check_output_folder` refuse bad output paths before any work, :func:`check_distinct` two
  outputs of one run at the same path or one inside the other; :func:`output_folder` creates the
  folder and holds an exclusive ``fcntl.flock`` on it (one run per folder);
- :mod:`~bearnav_cli.artifacts.ownership` — **never replace what bearnav did not write**:
  :func:`written_by` tells which command wrote a file or a bag (its manifest, the marker line of a
  ``tags`` map, the custom data of a bag); :func:`check_overwrite` refuses to replace anything
  else without ``--force``, :func:`check_plan_folder` a plan folder of another map;
- :mod:`~bearnav_cli.artifacts.records` — the sweep store: JSON records, CSV and Parquet tables.
"""

from bearnav_cli.artifacts.atomic import atomic_output, atomic_write, copy_file, remove_stale_temp_files, staging_folder
from bearnav_cli.artifacts.manifest import (
    ARTIFACT_FORMAT,
    KINDS,
    RETIRED_SCHEMAS,
    Kind,
    cache_key,
    content_hash,
    embedded_map_text,
    entries_of,
    kind_of_schema,
    make_manifest,
    params_dict,
    sha256_text,
    software_versions,
)
from bearnav_cli.artifacts.outputs import check_distinct, check_output_file, check_output_folder, output_folder
from bearnav_cli.artifacts.ownership import TAGS_MARKER, Origin, check_overwrite, check_plan_folder, written_by
from bearnav_cli.artifacts.reading import Loaded, fresh, load, map_source_of, read_input, read_manifest
from bearnav_cli.artifacts.records import read_record, write_parquet, write_record, write_table
from bearnav_cli.artifacts.writing import metrics_path, output_files, save
from bearnav_cli.runtime.plan_file import canonical_json, memory_budget

#: Every name of the modules' ``__all__`` the package has always exported, and three of the robot's reader
#: (``runtime.plan_file``) the CLI, the pipeline and the sweep use through it.
__all__ = [
    "ARTIFACT_FORMAT",
    "atomic_output",
    "atomic_write",
    "cache_key",
    "canonical_json",
    "check_distinct",
    "check_output_file",
    "check_output_folder",
    "check_overwrite",
    "check_plan_folder",
    "content_hash",
    "copy_file",
    "embedded_map_text",
    "entries_of",
    "fresh",
    "Kind",
    "kind_of_schema",
    "KINDS",
    "load",
    "Loaded",
    "make_manifest",
    "map_source_of",
    "memory_budget",
    "metrics_path",
    "Origin",
    "output_files",
    "output_folder",
    "params_dict",
    "read_input",
    "read_manifest",
    "read_record",
    "remove_stale_temp_files",
    "RETIRED_SCHEMAS",
    "save",
    "sha256_text",
    "software_versions",
    "staging_folder",
    "TAGS_MARKER",
    "write_parquet",
    "write_record",
    "write_table",
    "written_by",
]
