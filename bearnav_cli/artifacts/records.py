"""The sweep store of ``bearnav sweep``: small JSON records, and the results as CSV and Parquet tables."""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from bearnav_cli.artifacts.atomic import atomic_output, atomic_write
from bearnav_cli.artifacts.reading import read_file
from bearnav_cli.errors import ArtifactError

__all__ = ["read_record", "write_parquet", "write_record", "write_table"]


def write_record(path: str | os.PathLike, document: dict) -> None:
    """Write one small JSON record of the sweep store (a job, a plan's provenance) atomically.

    NaN and infinities are written as ``null`` (JSON has neither); the folder is created.
    """

    def clean(value: Any) -> Any:
        if isinstance(value, float) and not np.isfinite(value):
            return None
        if isinstance(value, dict):
            return {str(k): clean(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [clean(v) for v in value]
        return value

    text = json.dumps(clean(document), indent=1, sort_keys=True, allow_nan=False) + "\n"
    atomic_write(path, lambda handle: handle.write(text.encode()))


def read_record(path: str | os.PathLike, schema: str) -> dict | None:
    """A record :func:`write_record` wrote with this ``schema``, or None (missing, unreadable, another schema)."""
    try:  # through the one reader of input files: a FIFO or a huge file in the store is refused, not read
        document = json.loads(read_file(Path(path)).decode("utf-8"))
    except (ArtifactError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(document, dict) or document.get("schema") != schema:
        return None
    return document


def write_table(path: str | os.PathLike, columns: tuple[str, ...], rows: list[dict]) -> Path:
    """Write ``rows`` as CSV (a header of ``columns``, None as an empty cell) atomically; returns ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write (replaced atomically).
    columns : tuple of str
        The column names, in order.
    rows : list of dict
        One dict per row, column name → value (a missing or None value is an empty cell).
    """
    import csv

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    writer.writerows([{c: ("" if row.get(c) is None else row.get(c)) for c in columns} for row in rows])
    data = buffer.getvalue().encode()
    atomic_write(path, lambda handle: handle.write(data))
    return Path(path)


def write_parquet(path: str | os.PathLike, columns: tuple[str, ...], rows: list[dict]) -> Path | None:
    """Write ``rows`` as Parquet atomically when pyarrow is installed (else nothing, None).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write (replaced atomically).
    columns : tuple of str
        The column names, in order.
    rows : list of dict
        One dict per row, column name → value (a missing value is null).
    """
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    table = pa.table({c: [row.get(c) for row in rows] for c in columns})
    with atomic_output(path) as tmp:
        pq.write_table(table, str(tmp))
    return Path(path)
