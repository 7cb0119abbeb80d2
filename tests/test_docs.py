"""docs/artifacts.md and artifacts.KINDS must describe the same entries."""

from __future__ import annotations

import re

from bearnav_cli.artifacts import KINDS

from .conftest import REPO


def documented_entries() -> dict[str, dict[str, tuple[str, int]]]:
    """Parse every ``## file — `schema` `` section's ``| key | dtype | ndim |`` table."""
    text = (REPO / "docs" / "artifacts.md").read_text()
    sections = re.split(r"^## ", text, flags=re.M)[1:]
    found = {}
    for section in sections:
        head = re.match(r".*`(bearnav\.[a-z]+/\d+)`", section.splitlines()[0])
        if not head:
            continue
        rows = re.findall(r"^\| `(\w+)` \| (\w) \| (\d) \|", section, flags=re.M)
        found[head.group(1)] = {key: (kind, int(ndim)) for key, kind, ndim in rows}
    return found


def test_every_artifact_kind_is_documented_exactly():
    docs = documented_entries()
    for kind in KINDS.values():
        assert kind.schema in docs, f"{kind.schema} missing from docs/artifacts.md"
        assert docs[kind.schema] == kind.entries, kind.schema
    assert set(docs) == {kind.schema for kind in KINDS.values()}
