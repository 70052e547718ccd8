"""Run manifest: atomic JSON, numpy values converted, key order kept, NaN refused."""

import json
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.errors import InputError
from bpy_pipeline.io import read_manifest, write_manifest


def test_round_trip_with_numpy_values_and_key_order(tmp_path):
    manifest = {
        "seed": np.int64(7),
        "config": {"sensor": {"preset": "vlp16", "position": np.array([0.0, 0.0, 1.5])}},
        "frames": [{"index": 0, "points": np.uint32(123), "files": [Path("ply/000000.ply")], "scan_s": np.float32(0.5)}],
        "a_last_key": True,
    }
    path = write_manifest(tmp_path / "out", manifest)
    assert path == tmp_path / "out" / "manifest.json"
    text = path.read_text()
    assert text.endswith("}\n") and '\n  "seed": 7,' in text
    back = read_manifest(tmp_path / "out")
    assert list(back) == ["seed", "config", "frames", "a_last_key"]
    assert back["config"]["sensor"]["position"] == [0.0, 0.0, 1.5]
    assert back["frames"][0] == {"index": 0, "points": 123, "files": ["ply/000000.ply"], "scan_s": 0.5}
    assert json.loads(text) == back


def test_nan_and_unknown_types_refused_and_old_manifest_kept(tmp_path):
    write_manifest(tmp_path, {"seed": 1})
    with pytest.raises(ValueError, match="manifest.json"):
        write_manifest(tmp_path, {"seed": 2, "scan_s": float("nan")})
    with pytest.raises(ValueError, match="object"):
        write_manifest(tmp_path, {"seed": 3, "what": object()})
    assert read_manifest(tmp_path) == {"seed": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["manifest.json"]


def test_reader_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="manifest.json"):
        read_manifest(tmp_path)
    (tmp_path / "manifest.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="JSON object"):
        read_manifest(tmp_path)
    (tmp_path / "manifest.json").write_text("{nope")
    with pytest.raises(InputError, match="not valid JSON"):
        read_manifest(tmp_path)
