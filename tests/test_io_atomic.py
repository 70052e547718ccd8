"""atomic_write / atomic_dir: nothing half-written under a final name, no temporary left behind."""

import pytest

from bpy_pipeline.io import atomic_dir, atomic_write, write_ply
from bpy_pipeline.io.atomic import HashedFile
from bpy_pipeline.lidar.points import empty_points


def test_atomic_write_renames_temporary_on_success(tmp_path):
    target = tmp_path / "a" / "b" / "frame.bin"
    with atomic_write(target) as tmp:
        assert tmp.parent == target.parent and tmp.parent.is_dir()
        assert tmp.name.startswith(".") and tmp.name.endswith(".tmp")
        tmp.write_bytes(b"payload")
        assert not target.exists()
    assert target.read_bytes() == b"payload"
    assert sorted(p.name for p in target.parent.iterdir()) == ["frame.bin"]


def test_atomic_write_removes_temporary_and_keeps_old_file_on_error(tmp_path):
    target = tmp_path / "frame.bin"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_write(target) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("boom")
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["frame.bin"]


def test_atomic_write_fails_when_nothing_was_written(tmp_path):
    with pytest.raises(FileNotFoundError):
        with atomic_write(tmp_path / "x.bin"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_atomic_dir_replaces_whole_folder_or_nothing(tmp_path):
    target = tmp_path / "frame"
    target.mkdir()
    (target / "stale.npy").write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_dir(target) as tmp:
            (tmp / "new.npy").write_bytes(b"half")
            raise RuntimeError("boom")
    assert [p.name for p in target.iterdir()] == ["stale.npy"]
    assert [p.name for p in tmp_path.iterdir()] == ["frame"]
    with atomic_dir(target) as tmp:
        assert tmp.name.startswith(".") and tmp.name.endswith(".tmp")
        (tmp / "new.npy").write_bytes(b"new")
    assert [p.name for p in target.iterdir()] == ["new.npy"]
    assert [p.name for p in tmp_path.iterdir()] == ["frame"]


def test_writer_failing_mid_write_leaves_no_file(tmp_path, monkeypatch):
    real = HashedFile.write

    def failing(self, data):  # the header goes through, then the disk fills part-way into the records
        if self.size:
            self.raw.write(b"partial")
            raise OSError("No space left on device")
        return real(self, data)

    monkeypatch.setattr(HashedFile, "write", failing)
    target = tmp_path / "ply" / "000000.ply"
    with pytest.raises(OSError, match="No space"):
        write_ply(target, empty_points(10))
    assert list(target.parent.iterdir()) == []


def test_text_written_hashed_has_the_bytes_and_digest_of_write_text(tmp_path):
    """write_text_hashed writes what Path.write_text writes (encoding, newlines) and records its sha256 at the rename."""
    import hashlib
    import os

    from bpy_pipeline.io.atomic import atomic_write, digests_while_writing, write_text_hashed

    text = "Car 0.0000 0 -1.5708 10.00 20.00\nPedestrian 1\n\nDontCare -1\n"
    (tmp_path / "plain.txt").write_text(text)
    with digests_while_writing() as digests:
        with atomic_write(tmp_path / "hashed.txt") as tmp:
            write_text_hashed(tmp, text)
    data = (tmp_path / "hashed.txt").read_bytes()
    assert data == (tmp_path / "plain.txt").read_bytes()
    assert digests[os.path.abspath(tmp_path / "hashed.txt")] == hashlib.sha256(data).hexdigest()


def test_a_large_buffer_is_written_in_slices_with_its_bytes_and_digest(tmp_path):
    """HashedFile hands the kernel at most WRITE_SLICE bytes a call (one call of a few MB can cost ten times the kernel
    time), and the file holds the buffer's bytes, its digest their sha256, recorded at the rename."""
    import hashlib
    import os

    import numpy as np

    from bpy_pipeline.io import atomic
    from bpy_pipeline.io.atomic import atomic_write, digests_while_writing, hashed_open

    data = np.random.default_rng(5).random(3 * atomic.WRITE_SLICE // 8 + 77)  # 3 slices and a part
    calls = []
    with digests_while_writing() as digests:
        with atomic_write(tmp_path / "big.bin") as tmp, hashed_open(tmp) as handle:
            real = handle.raw.write
            handle.raw.write = lambda part: calls.append(len(part)) or real(part)
            handle.write(b"head")
            handle.write(data)
    written = (tmp_path / "big.bin").read_bytes()
    assert written == b"head" + data.tobytes()
    assert digests[os.path.abspath(tmp_path / "big.bin")] == hashlib.sha256(written).hexdigest()
    assert max(calls) <= atomic.WRITE_SLICE and sum(calls) == len(written) and len(calls) == 1 + 4
