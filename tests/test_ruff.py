"""``ruff check`` passes on the repository, with the configuration in pyproject.toml ([tool.ruff])."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def ruff() -> list[str] | None:
    """The command that runs ruff: the one beside this Python, on PATH, or ``python -m ruff``; ``None`` when absent."""
    beside = Path(sys.executable).with_name("ruff")
    if beside.exists():
        return [str(beside)]
    if shutil.which("ruff"):
        return [shutil.which("ruff")]
    probe = subprocess.run([sys.executable, "-m", "ruff", "--version"], capture_output=True)
    return [sys.executable, "-m", "ruff"] if probe.returncode == 0 else None


def test_ruff_check_passes():
    command = ruff()
    if command is None:
        pytest.skip("ruff is not installed (pip install -e '.[test]' brings it)")
    done = subprocess.run([*command, "check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_ruff_reads_the_project_configuration():
    """The check above runs the rules pyproject.toml selects (else it could pass on an empty rule set)."""
    command = ruff()
    if command is None:
        pytest.skip("ruff is not installed (pip install -e '.[test]' brings it)")
    done = subprocess.run([*command, "check", "--show-settings", "bpy_pipeline/api.py"], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0 and "line_length = 160" in done.stdout and "unused-import (F401)" in done.stdout, done.stdout[-2000:]
