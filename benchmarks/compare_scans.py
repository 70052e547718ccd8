"""Two runs' frames point by point: how far the points moved and whether their labels changed.

``python benchmarks/compare_scans.py BEFORE AFTER`` (two ``--out`` folders of ``run.py`` with PLY output)
prints, per frame, the point counts, the largest distance between the points of the same beam
(ring, time and place among the points of that ring and time), and the points whose semantic or instance label differs. Used to show that a
change of how a scene is built (e.g. pieces placed by Geometry Nodes) leaves the scan as it was.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def beam_keys(record) -> np.recarray:
    """(n,) keys naming each point's beam: its ring, its firing time and its place among the points of equal
    ring and time (sensors that fire a ring's beams at once, dual returns), in the file's order."""
    ring_time = np.rec.fromarrays([record["ring"], record["time"]])
    order = np.argsort(ring_time, kind="stable")
    sorted_keys = ring_time[order]
    starts = np.r_[True, sorted_keys[1:] != sorted_keys[:-1]]
    first = np.maximum.accumulate(np.where(starts, np.arange(len(order)), 0))
    nth = np.empty(len(order), dtype=np.int64)
    nth[order] = np.arange(len(order)) - first
    return np.rec.fromarrays([record["ring"], record["time"], nth])


def compare(before: Path, after: Path) -> dict:
    """``{frame stem: {"points": (n_before, n_after), "matched", "max_moved_m", "label_changes", "same_beams"}}``."""
    from bpy_pipeline.io import read_ply

    out = {}
    for ply in sorted((before / "ply").glob("*.ply")):
        a, b = read_ply(ply), read_ply(after / "ply" / ply.name)
        ka, kb = beam_keys(a), beam_keys(b)
        common, ia, ib = np.intersect1d(ka, kb, return_indices=True)
        xyz = lambda r, i: np.column_stack([r["x"][i], r["y"][i], r["z"][i]]).astype(float)  # noqa: E731
        moved = np.linalg.norm(xyz(a, ia) - xyz(b, ib), axis=1)
        labels = (a["semantic"][ia] != b["semantic"][ib]) | (a["instance"][ia] != b["instance"][ib])
        out[ply.stem] = {"points": (len(a), len(b)), "matched": len(common), "max_moved_m": float(moved.max(initial=0.0)),
                         "moved_over_1mm": int((moved > 1e-3).sum()), "label_changes": int(labels.sum())}
    return out


if __name__ == "__main__":
    print(json.dumps(compare(Path(sys.argv[1]), Path(sys.argv[2])), indent=1))
