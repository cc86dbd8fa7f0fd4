"""Lint: `ruff check` over the repository with the `[tool.ruff]` configuration of pyproject.toml.

Same check as `make lint`. Fix findings with `ruff check --fix .` (import order, unused imports,
pyupgrade) and by hand for the rest; the rule set and its exceptions are documented in pyproject.toml.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _ruff() -> str:
    try:
        from ruff.__main__ import find_ruff_bin
    except ImportError:
        pytest.fail("ruff is not installed: pip install -e '.[test]' (ruff is in the test extra)")
    return str(find_ruff_bin())


def test_ruff_check_is_clean():
    result = subprocess.run([_ruff(), "check", "--no-cache", "--output-format", "concise", "."],
                            cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, f"ruff check found problems:\n{result.stdout}{result.stderr}"
