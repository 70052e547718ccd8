"""setup.sh finds what a Debian machine lacks: nothing, once it has run (the README's install), and bad arguments in one line."""

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux") or not (shutil.which("bash") and shutil.which("apt-get")),
                                reason="setup.sh is a bash script for Debian (bash and apt-get)")


def setup(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(ROOT / "setup.sh"), *args], capture_output=True, text=True, timeout=60)


def test_after_setup_nothing_is_missing():
    """The suite runs where setup.sh has installed what it found missing, so it now finds nothing. (Its check for
    Mesa's software GL listed a second path that exists nowhere, which failed the check everywhere: it asked for
    libgl1-mesa-dri on every run, and stopped a user who is not root.)"""
    extras = ["test"] if importlib.util.find_spec("lightgbm") else []  # `test` also asks for LightGBM's OpenMP runtime
    done = setup(*extras, "--missing")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "", f"setup.sh would install: {done.stdout.strip()}"


def test_an_unknown_argument_is_one_line_and_exit_2():
    done = setup("tests")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == ["setup.sh: unknown argument 'tests'; allowed: test, --missing"]
    assert done.stdout == ""
