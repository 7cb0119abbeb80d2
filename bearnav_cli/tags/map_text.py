"""The map with the proposed tags: appended to its description, or to the YAML text the user wrote (comments kept)."""

from __future__ import annotations

import copy
import json
import re
from typing import Any

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.tags.proposal import TagProposal

__all__ = ["map_spec_with_tags", "map_text_with_tags", "tagged_name"]


def map_spec_with_tags(spec: dict, proposal: TagProposal) -> dict:
    """A map description (DESIGN §4, as ``yaml.safe_load`` returns it) with the proposed tags appended.

    The existing landmarks and every other key are kept as they are (a deep copy: ``spec`` itself is
    not changed); each new tag is appended as ``{id, position: [x, y]}``.

    Parameters
    ----------
    spec : dict
        The map description the plan was made from.
    proposal : TagProposal
        The tags to add (:func:`propose_tags`): their ``ids`` and ``positions``.

    Returns
    -------
    dict

    Raises
    ------
    InvalidParamsError
        ``spec`` has no landmark list, or one of its ids is a proposed id (the proposal belongs to
        another map).
    """
    if not isinstance(spec, dict) or not isinstance(spec.get("landmarks"), list):
        raise InvalidParamsError("the map description has no list of landmarks", field="landmarks")
    out = copy.deepcopy(spec)
    ids = set()
    for k, item in enumerate(out["landmarks"]):
        ids.add(str(item.get("id", k)) if isinstance(item, dict) else str(k))
    clash = sorted(ids & set(proposal.ids))
    if clash:
        raise InvalidParamsError(
            f"proposed id {clash[0]!r} is already a landmark of this map description (was the plan made from it?)",
            field="landmarks",
        )
    for name, p in zip(proposal.ids, proposal.positions, strict=True):
        out["landmarks"].append({"id": name, "position": [float(p[0]), float(p[1])]})
    return out


def tagged_name(name: str) -> str:
    """The ``name:`` of a map with proposed tags: ``NAME_tags``, so that its plan folder is not the original's."""
    return name if name.endswith("_tags") else f"{name}_tags"


_TOP_KEY = re.compile(r"^(?P<key>[A-Za-z_][\w-]*)\s*:(?P<rest>.*)$")


def _top_key(line: str, key: str) -> re.Match | None:
    match = _TOP_KEY.match(line.rstrip("\r\n"))
    return match if match and match.group("key") == key else None


def _flow_item(name: str, p: Any) -> str:
    # JSON strings are YAML double-quoted scalars; repr of a float reads back as the same float
    return f"{{id: {json.dumps(name)}, position: [{float(p[0])!r}, {float(p[1])!r}]}}"


def map_text_with_tags(text: str, proposal: TagProposal, name: str, header: str) -> str | None:
    """The YAML text of a map description with the proposed tags appended and ``name:`` set, the rest as it was.

    Comments, key order, circles and every other key keep their text: only the ``name:`` line is
    replaced (or added after the header) and one line per new tag is added at the end of the
    top-level ``landmarks:`` list (a block list, or a flow list on one line). A first line that
    starts like ``header`` (an earlier run's) is replaced by ``header``.

    Parameters
    ----------
    text : str
        The map YAML as the user wrote it.
    proposal : TagProposal
        The tags to add: their ``ids`` and ``positions``.
    name : str
        The new map's ``name:`` (:func:`tagged_name`).
    header : str
        A comment line (starting with ``#``, no newline) put first.

    Returns
    -------
    str or None
        The new text, or None for a layout this edit does not handle (no top-level ``landmarks:``,
        a flow list over several lines); the caller checks that the text reads back as the map it
        means (``map_spec_with_tags`` and the new name) and writes the map afresh otherwise.
    """
    lines = text.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines[-1] += "\n"
    if lines and lines[0].startswith(header.split(":")[0] + ":"):
        lines = lines[1:]
    items = [_flow_item(ident, p) for ident, p in zip(proposal.ids, proposal.positions, strict=True)]
    at = next((i for i, line in enumerate(lines) if _top_key(line, "landmarks")), None)
    if at is None:
        return None
    rest = _top_key(lines[at], "landmarks").group("rest")
    value = rest.split(" #")[0].strip()
    if value.startswith("["):
        if not value.endswith("]"):
            return None  # a flow list over several lines
        head, _, tail = lines[at].rpartition("]")
        inner = value[1:-1].strip()
        lines[at] = head + (", " if inner else "") + ", ".join(items) + "]" + tail
    elif value:
        return None  # an alias or some other scalar: not a list this edit understands
    elif items:
        end, indent = at + 1, None
        for i in range(at + 1, len(lines)):
            stripped = lines[i].strip()
            if stripped and not lines[i][0].isspace() and not stripped.startswith(("-", "#")):
                break  # the next top-level key
            if stripped and not stripped.startswith("#"):
                end = i + 1
                if indent is None and stripped.startswith("-"):
                    indent = lines[i][: len(lines[i]) - len(lines[i].lstrip())]
        if indent is None:
            return None  # `landmarks:` with nothing under it (null)
        lines[end:end] = [f"{indent}- {item}\n" for item in items]
    named = next((i for i, line in enumerate(lines) if _top_key(line, "name")), None)
    if named is not None:
        lines[named] = f"name: {json.dumps(name)}\n"
    else:
        lines.insert(0, f"name: {json.dumps(name)}\n")
    return header + "\n" + "".join(lines)
