"""docs/artifacts.md and the one artifact schema (``bearnav_cli.runtime.schema``) must describe the same entries."""

from __future__ import annotations

import re

from bearnav_cli.artifacts import KINDS
from bearnav_cli.runtime import schema

from .conftest import REPO

#: A row of an entry table: key, dtype, shape, meaning (``\\|`` is a literal bar inside a cell).
_ROW = re.compile(r"^\| `(\w+)` \| (\w+) \| (\([^|]*\)) \| ((?:[^|\\]|\\.)*?) \|$", re.M)


def documented_entries() -> dict[str, tuple[dict[str, tuple[str, str, str]], str | None]]:
    """``{schema: ({key: (dtype, shape, meaning)}, dimensions line)}`` from every ``## file — `schema` `` section's
    ``| key | dtype | shape | meaning |`` table and the ``Dimensions:`` line under it."""
    text = (REPO / "docs" / "artifacts.md").read_text()
    found = {}
    for section in re.split(r"^## ", text, flags=re.M)[1:]:
        head = re.match(r".*`(bearnav\.[a-z]+/\d+)`", section.splitlines()[0])
        if not head or "| key | dtype | shape | meaning |" not in section:
            continue
        rows = {key: (dtype, shape, text.replace("\\|", "|")) for key, dtype, shape, text in _ROW.findall(section)}
        dims = re.search(r"^Dimensions: (.*)$", section, flags=re.M)
        found[head.group(1)] = (rows, dims.group(1) if dims else None)
    return found


def declared(kind: str) -> dict[str, tuple[str, str, str]]:
    return {key: (e.dtype, schema.shape_text(e.shape), e.meaning) for key, e in schema.ENTRIES[kind].items()}


def test_every_artifact_kind_is_documented_exactly():
    docs = documented_entries()
    for kind in KINDS.values():
        assert kind.entries is schema.ENTRIES[kind.name], f"{kind.name}: artifacts.KINDS must read the schema"
        assert kind.schema == schema.SCHEMAS[kind.name]
        if kind.name == "map":  # map.json is a JSON document: its fields have their own table
            assert kind.schema not in docs
            continue
        assert kind.schema in docs, f"{kind.schema} has no entry table in docs/artifacts.md"
        rows, dims = docs[kind.schema]
        assert rows == declared(kind.name), kind.schema
        wanted = ", ".join(f"`{k}` {v}" for k, v in schema.DIMENSIONS[kind.name].items()) + "."
        assert dims == wanted, f"{kind.schema}: the Dimensions line"
    assert set(docs) == {kind.schema for kind in KINDS.values()} - {KINDS["map"].schema}


def test_every_dimension_is_explained():
    """Each symbolic shape parses and names only dimensions listed for its kind."""
    for kind, entries in schema.ENTRIES.items():
        for key, entry in entries.items():
            for item in entry.shape:
                assert isinstance(item, int) or re.fullmatch(r"\d*[A-Z](\+\d+)?", item), (kind, key, item)
                if isinstance(item, str):
                    assert re.sub(r"[^A-Z]", "", item) in schema.DIMENSIONS[kind], (kind, key, item)


def test_the_runtime_reads_a_subset_of_the_plan():
    assert set(schema.RUNTIME_KEYS) <= set(schema.ENTRIES["plan"])


def test_the_architecture_table_names_every_module_and_the_layers():
    """docs/architecture.md's package table has one row per module of the package (and none for a module
    that is gone), and its layering block names every layer of tests/test_layering.py."""
    from .test_layering import LAYERS

    text = (REPO / "docs" / "architecture.md").read_text()
    rows = set(re.findall(r"^\| `([a-z_/]+\.py)` \|", text, flags=re.M))
    package = REPO / "bearnav_cli"
    modules = {
        str(p.relative_to(package)) for p in package.rglob("*.py") if p.name not in ("__init__.py", "__main__.py")
    }
    assert modules - rows == set(), f"modules without a row in docs/architecture.md: {sorted(modules - rows)}"
    assert rows - modules == set(), f"rows for modules that do not exist: {sorted(rows - modules)}"
    block = text[text.index("## Import layering") :]
    block = block[block.index("```") : block.index("```", block.index("```") + 3)]
    named = set(re.findall(r"[a-z_]+", block))
    missing = {layer for layer in LAYERS if layer not in named}
    assert not missing, f"layers missing from the layering block: {sorted(missing)}"
