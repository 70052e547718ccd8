"""Same config, same seed, same bytes: every builder's frames match the records made by the code
before the round's restructuring (tests/golden/golden.json, written by ``tests/golden/jobs.py record``).

The records hold the canonical point records and the SemanticKITTI files, so a writer may change
its layout without breaking the check, but no point may move. Digests are kept per Blender release
series (bpy major.minor: its mesh code, and the numpy it needs, may round differently), so the check
runs on every Blender that has an entry; one without skips, naming how to record its entry.
"""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))

import jobs

GOLDEN = jobs.read_golden()["by_blender"]


def recorded() -> dict:
    """This Blender's entry of the digests table; skips (naming how to record one) when there is none."""
    key = jobs.blender_key()
    if key not in GOLDEN:
        pytest.skip(
            f"no golden digests for Blender {key} (recorded: {', '.join(GOLDEN)}): after checking that the code has not changed "
            f"the bytes on a recorded Blender, run `python tests/golden/jobs.py record` with this bpy to add its entry"
        )
    return GOLDEN[key]


def test_the_table_is_keyed_by_release_series():
    for key, entry in GOLDEN.items():
        assert key == "{}.{}".format(*entry["versions"]["blender"].split(".")[:2])
        assert set(entry["jobs"]) == set(jobs.JOBS)


@pytest.mark.bpy
@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(jobs.JOBS))
def test_frames_keep_their_bytes(name, tmp_path):
    entry = recorded()
    got = jobs.run_job(name, tmp_path / name)
    assert got == entry["jobs"][name], f"recorded with {entry['versions']}, this is {jobs.versions()}"
