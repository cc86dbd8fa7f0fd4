"""The README's Python examples run.

Every fenced block that opens with ```python in README.md is executed, in order, in one namespace (as a
reader pasting them into one session would), with the repository root as the working directory.

Marker convention: a block whose first line is ``# readme-test: skip`` (optionally followed by ``-- reason``)
is not executed, e.g. a block that trains a driver or runs for minutes. Shell blocks (```bash, ```) are
never executed here; the CLI has its own tests.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
SKIP_MARKER = re.compile(r"^#\s*readme-test:\s*skip\b(?:\s*--\s*(?P<reason>.*))?")
FENCE = re.compile(r"^```python[ \t]*\n(?P<code>.*?)^```[ \t]*$", re.M | re.S)


def python_blocks(text: str) -> list[tuple[int, str]]:
    """(line number of the opening fence, code) of each ```python block of a Markdown text."""
    return [(text.count("\n", 0, m.start()) + 1, m.group("code")) for m in FENCE.finditer(text)]


BLOCKS = python_blocks(README.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def namespace():
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        yield {"__name__": "readme"}
    finally:
        os.chdir(cwd)


def test_readme_has_python_examples():
    assert BLOCKS, "README.md has no ```python blocks"


@pytest.mark.parametrize("line, code", BLOCKS, ids=[f"README.md:{line}" for line, _ in BLOCKS])
def test_readme_block(line, code, namespace):
    first = code.lstrip().splitlines()[0] if code.strip() else ""
    marker = SKIP_MARKER.match(first)
    if marker:
        pytest.skip(f"README.md:{line}: marked '# readme-test: skip' {marker.group('reason') or ''}".rstrip())
    exec(compile(code, f"README.md:{line}", "exec"), namespace)


@pytest.mark.parametrize("text, expected", [
    ("x\n```python\na = 1\n```\n", [(2, "a = 1\n")]),
    ("```python\n# readme-test: skip -- trains\nb\n```\n```bash\nls\n```\n", [(1, "# readme-test: skip -- trains\nb\n")]),
])
def test_block_extraction(text, expected):
    assert python_blocks(text) == expected
