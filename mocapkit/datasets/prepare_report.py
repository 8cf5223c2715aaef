"""What the reports of the ``prepare`` commands share: skip counts, ``report.txt`` layout, writing.

:class:`~mocapkit.datasets.ntu.prepare.PrepareReport` (NTU ``.skeleton`` files) and
:class:`~mocapkit.datasets.casia_b.prepare.GEIPrepareReport` (CASIA-B sequences) derive from
:class:`PrepareReportBase`. Each is written beside its cache as ``report.json``
(:meth:`~PrepareReportBase.to_dict`) and ``report.txt`` (:meth:`~PrepareReportBase.to_text`).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

from mocapkit.io_atomic import atomic_write_text

REPORT_JSON = "report.json"
REPORT_TXT = "report.txt"


class PrepareReportBase:
    """Base of the prepare reports (dataclasses with a ``skipped`` list of dicts holding a ``"reason"``).

    A subclass gives :meth:`totals` (name -> count, in report order), :meth:`to_dict` (``report.json``),
    and for ``report.txt`` its title lines (:meth:`_text_title`) and its listed items
    (:meth:`_text_sections`).
    """

    skipped: list[dict]

    def count(self, reason: str) -> int:
        """Number of skipped items (files or sequences) with this ``reason``."""
        return sum(1 for s in self.skipped if s["reason"] == reason)

    def totals(self) -> dict:  # pragma: no cover - implemented by subclasses
        raise NotImplementedError

    def to_dict(self) -> dict:  # pragma: no cover - implemented by subclasses
        raise NotImplementedError

    def _text_title(self) -> list[str]:  # pragma: no cover - implemented by subclasses
        raise NotImplementedError

    def _text_sections(self) -> Iterable[tuple[str, int, list[str]]]:  # pragma: no cover
        """``(heading, count, lines)`` per section of ``report.txt``; no lines are written as ``none``."""
        raise NotImplementedError

    def to_text(self) -> str:
        """The human-readable ``report.txt``: the title, the totals, then every section."""
        lines = [*self._text_title(), ""]
        lines += [f"{key:>28}: {value}" for key, value in self.totals().items()]
        for heading, count, entries in self._text_sections():
            lines += ["", f"{heading} ({count}):"]
            lines += entries or ["  none"]
        return "\n".join(lines) + "\n"

    def write(self, folder: str | Path) -> None:
        """Write ``report.json`` and ``report.txt`` into ``folder`` (which must exist), each atomically."""
        folder = Path(folder)
        atomic_write_text(folder / REPORT_JSON, json.dumps(self.to_dict(), indent=1) + "\n")
        atomic_write_text(folder / REPORT_TXT, self.to_text())
