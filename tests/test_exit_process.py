"""cli.exit_process: the end of ``python run.py`` without the interpreter's teardown, and what it still does."""

import os
import subprocess
import sys
import types
from pathlib import Path

import pytest

from bpy_pipeline.cli import exit_process

ROOT = Path(__file__).resolve().parents[1]

PROGRAM = """
import atexit, sys, threading, time
from pathlib import Path
from bpy_pipeline.cli import exit_process

class Torn:
    def __del__(self):
        print("torn down")

kept = Torn()  # a normal exit tears it down and prints; exit_process must not spend that time
atexit.register(lambda: print("atexit ran"))

def late():
    time.sleep(0.3)
    Path(sys.argv[1]).write_text("written")

threading.Thread(target=late).start()
print("unflushed", end="")  # stdout is a pipe: block-buffered until flushed
exit_process(3)
"""


def test_waits_for_threads_runs_atexit_flushes_and_skips_the_teardown(tmp_path):
    marker = tmp_path / "late.txt"
    done = subprocess.run([sys.executable, "-c", PROGRAM, str(marker)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 3, done.stderr
    assert done.stdout == "unflushedatexit ran\n"
    assert marker.read_text() == "written"
    normal = subprocess.run([sys.executable, "-c", PROGRAM.replace("exit_process(3)", "sys.exit(3)"), str(marker)], cwd=ROOT, capture_output=True, text=True,
                            timeout=120)
    assert "torn down" in normal.stdout  # the teardown the other run skipped


def test_inside_blender_blender_ends_itself(monkeypatch):
    blender = types.SimpleNamespace(app=types.SimpleNamespace(binary_path="/usr/bin/blender"))
    monkeypatch.setitem(sys.modules, "bpy", blender)
    with pytest.raises(SystemExit) as ended:
        exit_process(5)
    assert ended.value.code == 5


def test_a_process_without_stdout_still_exits_with_its_code():
    program = "import sys; sys.stdout = None; from bpy_pipeline.cli import exit_process; exit_process(4)"
    done = subprocess.run([sys.executable, "-c", program], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 4 and done.stderr == ""


def test_no_blender_session_folder_is_left_behind(tmp_path):
    """The bpy module makes ``$TMPDIR/blender_XXXXXX`` at its import and only its teardown removes it: a run ended by
    exit_process (its bad-input exit here, and a plain exit after importing bpy) leaves the temporary folder as it was."""
    pytest.importorskip("bpy")
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    (temporary / "theirs").mkdir()  # somebody else's: stays
    env = {**os.environ, "TMPDIR": str(temporary)}
    program = "import bpy, sys; from bpy_pipeline.cli import exit_process; print(bpy.app.tempdir); exit_process(0)"
    done = subprocess.run([sys.executable, "-c", program], cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout.strip()).parent == temporary  # it was made where TMPDIR says
    bad = subprocess.run([sys.executable, "run.py", "--config", str(tmp_path / "missing.yaml"), "--out", str(tmp_path / "out")], cwd=ROOT,
                         capture_output=True, text=True, timeout=300, env=env)
    assert bad.returncode == 2, bad.stderr
    assert sorted(p.name for p in temporary.iterdir()) == ["theirs"]
