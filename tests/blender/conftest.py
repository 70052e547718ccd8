"""Fixtures of the real-Blender lane: chroots, the built extension, a work folder mounted into each chroot.

The lane runs only when ``BPY_PIPELINE_REAL_BLENDER=1`` (tests/blender/run_lane.sh sets it after
building or finding the chroots), so the normal suite stays fast; without it, or without the
chroots, every test here is skipped with the reason.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from realblender import CACHE, ROOT, SUITES, Chroot

ENABLED = os.environ.get("BPY_PIPELINE_REAL_BLENDER") == "1"


def pytest_configure(config):
    config.addinivalue_line("markers", "blender: needs a real Blender binary (tests/blender/run_lane.sh)")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if "tests/blender/" in str(item.fspath).replace(os.sep, "/"):
            item.add_marker(pytest.mark.blender)


@pytest.fixture(scope="session")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("real_blender")


@pytest.fixture(scope="session", params=list(SUITES), ids=list(SUITES))
def chroot(request, work):
    """A mounted chroot with a real Blender (the repository and ``work`` at their own paths)."""
    if not ENABLED:
        pytest.skip("real-Blender lane: run tests/blender/run_lane.sh (sets BPY_PIPELINE_REAL_BLENDER=1)")
    if os.geteuid() != 0:
        pytest.skip("real-Blender lane: chroot and mount need root")
    box = Chroot(request.param)
    if not box.ready():
        pytest.skip(f"no {SUITES[request.param]} chroot in {CACHE} (tests/blender/chroots.sh builds it)")
    box.mount(ROOT, work)
    request.addfinalizer(box.unmount)
    return box


@pytest.fixture(scope="session")
def extension_zip(work):
    """The extension for linux-x64, built by scripts/build_extension.py (cp311, cp313 and cp314 wheels)."""
    if not ENABLED:
        pytest.skip("real-Blender lane: run tests/blender/run_lane.sh")
    out = work / "dist"
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platform", "linux-x64", "--out", str(out)], capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    (path,) = result.stdout.split()
    return out / os.path.basename(path)
