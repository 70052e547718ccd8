"""The test lanes of tests/conftest.py name files and tests that exist (a renamed test would otherwise
drop out of its lane silently), and the marks reach the collected items."""

import ast
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
# by its path: `import conftest` may find tests/blender/conftest.py first
_spec = importlib.util.spec_from_file_location("lanes_conftest", TESTS / "conftest.py")
conftest = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(conftest)


def functions_of(file: str) -> set[str]:
    tree = ast.parse((TESTS / file).read_text())
    return {node.name for node in tree.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith("test_")}


@pytest.mark.parametrize("entry", sorted(conftest.SLOW | set(conftest.GROUPS)))
def test_every_lane_entry_names_a_test_file_or_test(entry):
    file, _, test = entry.partition("::")
    assert (TESTS / file).is_file(), f"{entry}: no tests/{file}"
    if test:
        assert test in functions_of(file), f"{entry}: tests/{file} has no {test}"


def test_marks_reach_the_items():
    class Item:  # what lane_marks reads of a collected item
        def __init__(self, nodeid):
            self.nodeid, self.path = nodeid, TESTS / nodeid.split("::")[0].split("/")[-1]

    slow = conftest.lane_marks(Item("tests/test_golden.py::test_frames_keep_their_bytes[parking]"))
    assert [m.name for m in slow] == ["slow"]
    grouped = conftest.lane_marks(Item("tests/test_dataset.py::test_records_hold_each_frame_and_the_manifest_is_written_once"))
    assert [(m.name, m.args) for m in grouped] == [("slow", ()), ("xdist_group", ("dataset",))]
    assert conftest.lane_marks(Item("tests/test_lanes.py::test_marks_reach_the_items")) == []


GROUPED_PROBE = '''
import os, pytest

@pytest.mark.parametrize("k", range(8))
def test_probe(k):
    with open(os.environ["LANES_PROBE_OUT"], "a") as f:
        f.write(os.environ.get("PYTEST_XDIST_WORKER", "main") + "\\n")
'''


def test_a_group_runs_on_one_xdist_worker(tmp_path):
    """The README's `-n auto --dist loadgroup` really keeps a group on one worker. pytest 9.2 stores a node's
    id where pytest-xdist 3.8 does not write it, so there every group was silently spread over the workers
    (two extension builds then raced on build/extension/); pyproject.toml pins pytest below 9.2 for it."""
    pytest.importorskip("xdist")
    (tmp_path / "conftest.py").write_text(
        "import pytest\n"
        "@pytest.hookimpl(tryfirst=True)\n"
        "def pytest_collection_modifyitems(config, items):\n"
        "    for item in items:\n"
        "        item.add_marker(pytest.mark.xdist_group('probe'))\n"
    )
    (tmp_path / "test_probe.py").write_text(GROUPED_PROBE)
    out = tmp_path / "workers.txt"
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadgroup", "-p", "no:cacheprovider", str(tmp_path)],
                            capture_output=True, text=True, timeout=120, cwd=tmp_path, env={**os.environ, "LANES_PROBE_OUT": str(out)})
    assert result.returncode == 0, result.stdout + result.stderr
    workers = out.read_text().split()
    assert len(workers) == 8 and len(set(workers)) == 1, workers
