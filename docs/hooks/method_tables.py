"""MkDocs hook: each task guide's table of registered methods, generated from the method registry.

``configs/<task>/method/*.yaml`` is the one list of methods (:mod:`mocapkit.train.registry`); this hook replaces
the marker ``<!-- methods: TASK -->`` in a page with the table ``mocapkit methods TASK`` prints (name, learned or
not, the one-line description, the class or experiment), so the docs list exactly the methods the commands accept.
"""

from __future__ import annotations

import re

MARKER = re.compile(r"<!-- methods: (\w+) -->")


def table(task: str) -> str:
    """The Markdown table of ``task``'s registered methods, its default marked."""
    from mocapkit.train.registry import default_method, describe

    default = default_method(task)
    lines = ["| method | learned | description | builds |", "|---|---|---|---|"]
    for row in describe(task):
        name = f"`{row.name}`" + (" (default)" if row.name == default else "")
        lines.append(
            f"| {name} | {'yes' if row.learned else 'no'} | {row.description.replace('|', '/')} | `{row.target}` |"
        )
    return "\n".join(lines)


def on_page_markdown(markdown: str, page, config, files) -> str:
    return MARKER.sub(lambda match: table(match.group(1)), markdown)
