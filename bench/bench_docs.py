"""Shared by the benchmark scripts: write a benchmark's section into docs/benchmarks.md."""

from __future__ import annotations

import re
from pathlib import Path


def write_section(heading: str, text: str, path: Path) -> None:
    """Replace the section of ``path`` that starts at the line ``heading`` (up to the next ``## ``
    heading) with ``text``, or append ``text`` when there is no such section."""
    document = path.read_text() if path.exists() else "# Benchmarks\n"
    pattern = re.compile(rf"^{re.escape(heading)}\n.*?(?=^## |\Z)", re.DOTALL | re.MULTILINE)
    if pattern.search(document):
        document = pattern.sub(lambda _: text + "\n", document, count=1)
    else:
        document = document.rstrip("\n") + "\n\n" + text + "\n"
    path.write_text(document.rstrip("\n") + "\n")
