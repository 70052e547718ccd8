"""The extension run from the checkout (docs/panel.md, "Run from the checkout"): linked into a fresh
user extension repository without a build, enabled, and its Scan and Generate undone
(tests/extension_checkout_session.py runs the Blender session)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.bpy, pytest.mark.slow]


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> dict:
    work = tmp_path_factory.mktemp("checkout")
    home = work / "home"
    env = dict(os.environ, HOME=str(home), BLENDER_USER_RESOURCES=str(home / "blender"))
    result = subprocess.run([sys.executable, str(ROOT / "tests" / "extension_checkout_session.py"), str(work)], capture_output=True, text=True, timeout=600,
                            env=env, cwd=work)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return json.loads((work / "report.json").read_text())


def test_the_checkout_runs_as_an_extension(report):
    assert report["enabled"] and report["runs_from_the_checkout"]
    assert not report["module_level_last"]  # the last frame lives on the window manager


def test_scan_and_generate_are_one_undo_step_each(report):
    assert report["scan"] == ["FINISHED"] and report["objects_after_scan"] == 2 and report["last_file_after_scan"]
    assert report["objects_after_undo"] == 0  # the scene Scan built is taken back
    assert report["show_cloud_after_undo"] == ["FINISHED"]  # the window manager's last frame is not undone
    assert report["generate"] == ["FINISHED"] and report["objects_after_generate"] == 2
    before, after = report["objects_after_generate_undo"]
    assert after == before


def test_disabling_drops_the_last_frame_and_its_file(report):
    assert not report["last_file_after_disable"] and not report["window_manager_property_after_disable"]
