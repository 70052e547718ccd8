"""The car bodies real-scan insertion draws (geometry/objects.py BODIES) against published car sizes.

Ours: length, width (without mirrors) and height of each of the 24 bodies at its nominal size (a
rule's car takes one of them, +-3 % in length and width). Published: (1) the labelled Car boxes of
the two KITTI object frames among the test scans (000008: 6 cars, 004747: 4; KITTI's annotators'
boxes, length x width x height); (2) the mean car sizes that mmdetection3d's detector configs use
as anchors for KITTI (3.9 x 1.6 x 1.56 m), Lyft (4.75 x 1.92 x 1.71 m) and Waymo (4.73 x 2.08 x 1.77 m),
each the mean of its dataset's car boxes. No timing: the figure is the comparison.
Run: python benchmarks/bench_car_bodies.py   (writes results/car_bodies.json and car_bodies.png)
"""

import json

import numpy as np
from common import ROOT, arguments, report

from bpy_pipeline.geometry.objects import BODIES, style_size

REAL = ROOT.parent / "shared" / "real_scans"
ANCHORS = {"KITTI (mmdetection3d anchor)": (3.9, 1.6, 1.56), "Lyft (mmdetection3d anchor)": (4.75, 1.92, 1.71),
           "Waymo (mmdetection3d anchor)": (4.73, 2.08, 1.77)}


def kitti_cars() -> np.ndarray:
    """``(n, 3)`` length, width, height of the labelled Car boxes of the KITTI frames among the test scans (empty if absent)."""
    out = []
    boxes = REAL / "kitti_000008_boxes.json"
    if boxes.exists():
        for b in json.loads(boxes.read_text())["boxes"]:
            if b["class"] == "Car":
                _, _, _, length, height, width, _ = b["box_cam_xyz_lhw_ry"]
                out.append((length, width, height))
    label = REAL / "kitti_004747_label_2.txt"
    if label.exists():
        for line in label.read_text().splitlines():
            words = line.split()
            if words and words[0] == "Car":
                height, width, length = (float(v) for v in words[8:11])
                out.append((length, width, height))
    return np.array(out, float).reshape(-1, 3)


def main() -> None:
    args = arguments(__doc__)
    sizes = np.array([style_size(b, b.height) for b in BODIES])
    kinds = [b.kind or b.name for b in BODIES]
    rows = []
    for kind in dict.fromkeys(kinds):
        s = sizes[[k == kind for k in kinds]]
        rows.append({"source": f"ours: {kind}", "n": len(s), **{f"{a}_m": f"{s[:, i].min():.2f}-{s[:, i].max():.2f}" for i,
                                                                a in enumerate(("length", "width", "height"))}})
    rows.append({"source": "ours: all", "n": len(sizes), **{f"{a}_m": f"{sizes[:, i].min():.2f}-{sizes[:, i].max():.2f}" for i,
                                                            a in enumerate(("length", "width", "height"))}})
    real = kitti_cars()
    if len(real):
        rows.append({"source": "KITTI labelled Car boxes (000008, 004747)", "n": len(real),
                     **{f"{a}_m": f"{real[:, i].min():.2f}-{real[:, i].max():.2f}" for i, a in enumerate(("length", "width", "height"))}})
    for name, (length, width, height) in ANCHORS.items():
        rows.append({"source": name, "n": 1, "length_m": f"{length:.2f}", "width_m": f"{width:.2f}", "height_m": f"{height:.2f}"})
    report("car_bodies", rows, args.out, {"bodies": {b.name: [round(float(v), 3) for v in style_size(b, b.height)] for b in BODIES}})
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    markers = dict(zip(dict.fromkeys(kinds), "osD^vP"))
    for ax, j, label in ((axes[0], 2, "height (m)"), (axes[1], 1, "width (m)")):
        for kind, m in markers.items():
            s = sizes[[k == kind for k in kinds]]
            ax.scatter(s[:, 0], s[:, j], marker=m, label=f"ours: {kind}")
        if len(real):
            ax.scatter(real[:, 0], real[:, j], marker="x", c="k", label="KITTI labelled cars")
        for name, size in ANCHORS.items():
            ax.scatter(size[0], size[j], marker="*", s=160, edgecolors="k", label=name)
        ax.set_xlabel("length (m)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, loc="lower right")
    fig.suptitle("Car bodies for insertion against published car sizes")
    fig.tight_layout()
    fig.savefig(args.out / "car_bodies.png", dpi=110)


if __name__ == "__main__":
    main()
