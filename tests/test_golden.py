"""Same config, same seed, same bytes: every builder's frames match the records made by the code
before the round's restructuring (tests/golden/golden.json, written by ``tests/golden/jobs.py record``).

The records hold the canonical point records and the SemanticKITTI files, so a writer may change
its layout without breaking the check, but no point may move. They are exact only for the
versions that made them; other versions skip with the reason.
"""

import json
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.bpy
sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))

import jobs  # noqa: E402

GOLDEN = json.loads(jobs.GOLDEN.read_text())


@pytest.mark.parametrize("name", sorted(jobs.JOBS))
def test_frames_keep_their_bytes(name, tmp_path):
    if jobs.versions() != GOLDEN["versions"]:
        pytest.skip(f"golden records were made with {GOLDEN['versions']}, this is {jobs.versions()}")
    assert jobs.run_job(name, tmp_path / name) == GOLDEN["jobs"][name]
