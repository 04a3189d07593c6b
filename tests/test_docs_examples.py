"""Every ```python block of docs/controllers.md, and the README's "Library use" block, runs as
written from the repository root, each in a fresh namespace: doc examples cannot rot."""

from __future__ import annotations

import re
from pathlib import Path

import numba
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _blocks(path: Path, section: str | None = None) -> list[tuple[str, str]]:
    """(id, code) of each ```python block, with its line number; within ``## section`` only
    when given."""
    text = path.read_text(encoding="utf-8")
    start, end = 0, len(text)
    if section is not None:
        head = re.search(rf"^## {re.escape(section)}\s*$", text, re.M)
        assert head, f"{path.name} has no section '## {section}'"
        start = head.end()
        nxt = re.search(r"^## ", text[start:], re.M)
        end = start + nxt.start() if nxt else end
    out = []
    for m in re.finditer(r"^```python\n(.*?)^```", text[start:end], re.S | re.M):
        line = text.count("\n", 0, start + m.start()) + 1
        out.append((f"{path.name}:{line}", m.group(1)))
    return out


BLOCKS = _blocks(ROOT / "docs" / "controllers.md") + _blocks(ROOT / "README.md", "Library use")


def test_the_pages_have_examples():
    assert sum(b[0].startswith("controllers.md") for b in BLOCKS) >= 6
    assert any(b[0].startswith("README.md") for b in BLOCKS)


@pytest.mark.parametrize("code", [b[1] for b in BLOCKS], ids=[b[0] for b in BLOCKS])
def test_example_runs(code, monkeypatch):
    monkeypatch.chdir(ROOT)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)  # small examples: the parallel ray caster's threads only cost
    try:
        exec(compile(code, "<doc example>", "exec"), {"__name__": "__doc_example__"})
    finally:
        numba.set_num_threads(threads)
