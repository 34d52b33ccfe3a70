"""Scenario files written from Python values, so a test states its components and
connections as data instead of repeating their TOML lines."""
from __future__ import annotations

import json
import re
from pathlib import Path


def _key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def _value(value) -> str:
    """A TOML value: a number, a string (or path), a list, or a dict as an inline table."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return str(value)                        # inf, nan and exponents are spelt as TOML spells them
    if isinstance(value, str | Path):
        return json.dumps(str(value))            # JSON's escapes are TOML's basic-string escapes
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + " }"
    return "[" + ", ".join(_value(v) for v in value) + "]"


def _is_tables(value) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _table(header: str, table: dict) -> list[str]:
    """``[header]`` or ``[[header]]`` lines: its values, then each list of dicts in it as
    ``[[header.key]]`` tables."""
    lines = [header] if header else []
    lines += [f"{_key(k)} = {_value(v)}" for k, v in table.items() if not _is_tables(v)]
    name = header.strip("[]")
    for k, items in table.items():
        if _is_tables(items):
            for item in items:
                lines += ["", *_table(f"[[{name}.{_key(k)}]]", item)]
    return lines


def toml_text(document: dict) -> str:
    """The TOML text of ``document``: its plain values first, then each dict as a ``[table]``
    and each list of dicts as ``[[tables]]`` (a dict inside those is an inline table)."""
    plain = {k: v for k, v in document.items() if not (isinstance(v, dict) or _is_tables(v))}
    lines = _table("", plain)
    for key, value in document.items():
        if isinstance(value, dict):
            lines += ["", *_table(f"[{_key(key)}]", value)]
        elif _is_tables(value):
            for item in value:
                lines += ["", *_table(f"[[{_key(key)}]]", item)]
    return "\n".join(lines).lstrip("\n") + "\n"


def write_scenario(path: Path, stop_time: float, components: list[dict], connections: dict | None = None,
                   **sections) -> Path:
    """Write a scenario file to ``path`` and return ``path``: ``[simulation]`` with
    ``stop_time`` [s], one ``[[component]]`` per dict of ``components``, the
    ``[connections]`` (input -> output) and any other top-level ``sections`` (a dict is a
    table, e.g. ``recording={"stream": True}``; anything else a plain value, e.g.
    ``plugins=[...]``)."""
    document = {**{k: v for k, v in sections.items() if not isinstance(v, dict)},
                "simulation": {"stop_time": stop_time}, "component": components}
    if connections:
        document["connections"] = connections
    document.update({k: v for k, v in sections.items() if isinstance(v, dict)})
    path.write_text(toml_text(document))
    return path


def component(kind: str, name: str, period: float, **keys) -> dict:
    """A ``[[component]]`` of type ``kind`` (``"fmu"``, ``"constant"``, ...) named ``name``,
    sampled every ``period`` [s], with its other ``keys``."""
    return {"name": name, "type": kind, "period": period, **keys}
