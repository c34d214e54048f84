"""Scene dicts as TOML text: one ``[section]`` per table, a ``key = value`` line per key, arrays and nested tables
inline on their line.

Every scalar (string, number, boolean, date) is written by tomli-w, which quotes and escapes strings as TOML
needs. The layout is kept here rather than left to ``tomli_w.dumps`` because the scene text of a ship case is
stored in its result file and compared byte for byte by the sweep (a rerun of a case whose scene text changed is
a new run): ``tomli_w.dumps`` would write each array over several lines and each nested table as a
``[section.key]`` table, so every stored case would read as a different scene.
"""

from __future__ import annotations

import tomli_w


def toml_value(value) -> str:
    """One value as it stands right of ``key =``: lists and dicts inline, scalars by tomli-w."""
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(_line(k, v) for k, v in value.items()) + " }"
    return tomli_w.dumps({"v": value})[len("v = "):-1]


def _line(key: str, value) -> str:
    """``key = value``; tomli-w writes the key (bare, or quoted where TOML needs it)."""
    return tomli_w.dumps({key: 0})[:-len(" = 0\n")] + " = " + toml_value(value)


def to_toml(data: dict) -> str:
    """TOML text of a scene dict (sections of scalars, lists and inline tables; a list of tables, such as
    ``bodies``, as ``[[section]]`` tables). TOML has no null: a key whose value is None is left out, which gives it
    its default (None for every optional scene key)."""
    lines = []
    for section, values in data.items():
        for header, table in ((f"[[{section}]]", t) for t in values) if isinstance(values, list) else \
                [(f"[{section}]", values)]:
            lines.append(header)
            lines += [_line(k, v) for k, v in table.items() if v is not None]
            lines.append("")
    return "\n".join(lines)
