"""scripts/check_upstream_loaders.py's numpy stand-ins for OpenPCDet's two compiled CPU functions agree with their C++."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "check_upstream_loaders.py"


@pytest.fixture(scope="module")
def check():
    spec = importlib.util.spec_from_file_location("check_upstream_loaders", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bev_iou_is_the_rotated_rectangles_overlap(check):
    a = np.array([[0, 0, 0, 4, 2, 1.5, 0.0]])
    turned = np.array([[0, 0, 5, 2, 4, 1.0, np.pi / 2]])  # the same footprint turned by 90 degrees, another height
    shifted = np.array([[2, 0, 0, 4, 2, 1.5, 0.0]])  # half of it over the first: 4 / (8 + 8 - 4)
    apart = np.array([[10, 0, 0, 4, 2, 1.5, 0.3]])
    diamond = np.array([[0, 0, 0, np.sqrt(2), np.sqrt(2), 1, np.pi / 4]])  # a unit-half-diagonal square inside a's 4 x 2
    got = check.bev_iou(a, np.concatenate([a, turned, shifted, apart, diamond]))
    np.testing.assert_allclose(got, [[1.0, 1.0, 1 / 3, 0.0, 2 / 8]], atol=1e-6)


def test_points_in_boxes_follows_roiaware_pool3d(check):
    box = np.array([[1.0, 2.0, 0.5, 4.0, 2.0, 1.0, np.pi / 6]])
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    local = np.array([[1.9, 0.9, 0.4], [2.005, 0.0, 0.0], [2.02, 0.0, 0.0], [0.0, 0.0, 0.51], [-1.9, -0.9, -0.5]])
    points = local @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) + box[0, :3]
    assert check.points_in_boxes(box, points.astype(np.float32)).tolist() == [[1, 1, 0, 0, 1]]  # 1 cm margin across, none along z
