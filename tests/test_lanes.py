"""The test lanes of tests/conftest.py name files and tests that exist (a renamed test would otherwise
drop out of its lane silently), and the marks reach the collected items."""

import ast
import importlib.util
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
