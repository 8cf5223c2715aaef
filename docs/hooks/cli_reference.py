"""MkDocs hook: the command-line reference of docs/cli.md, generated from the argparse parser.

``mocapkit.cli.build_parser()`` is the one description of the commands; this hook walks it at build time and
replaces the marker ``<!-- cli-reference -->`` in docs/cli.md with one section per command and subcommand
(its help line and its ``--help`` text), so the reference cannot drift from the code.
"""

from __future__ import annotations

import argparse
import os

MARKER = "<!-- cli-reference -->"
PAGE = "cli.md"
#: argparse wraps help text to the terminal width; a fixed width keeps the page the same on every machine.
WIDTH = "100"


def _subcommands(parser: argparse.ArgumentParser):
    """``(name, help, subparser)`` of each subcommand of ``parser``, in the order they were added."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help for choice in action._choices_actions}
            for name, sub in action.choices.items():
                yield name, helps.get(name), sub


def _sections(parser: argparse.ArgumentParser, path: list[str], level: int) -> list[str]:
    lines: list[str] = []
    for name, help_text, sub in _subcommands(parser):
        command = " ".join([*path, name])
        lines += [f"{'#' * level} `{command}`", ""]
        if help_text:
            lines += [help_text[0].upper() + help_text[1:] + ("" if help_text.endswith(".") else "."), ""]
        lines += ["```text", sub.format_help().rstrip(), "```", ""]
        lines += _sections(sub, [*path, name], min(level + 1, 4))
    return lines


def reference() -> str:
    """The generated Markdown: every command of ``mocapkit``, depth first."""
    from mocapkit.cli import build_parser

    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = WIDTH
    try:
        parser = build_parser()
        return "\n".join(_sections(parser, [parser.prog], 2))
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous


def on_page_markdown(markdown: str, page, config, files) -> str:
    if page.file.src_uri != PAGE:
        return markdown
    if MARKER not in markdown:
        raise ValueError(f"docs/{PAGE}: the marker {MARKER!r} is missing; the generated reference goes there")
    return markdown.replace(MARKER, reference())
