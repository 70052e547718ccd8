"""A user's files are never lost and never reached outside the output folder (issue 51, parts 1 and 2).

The dataset is written by ``bpy-pipeline convert`` (a street scan made here, no Blender), so every case runs
the real command, its real writers and the real dataset code. docs/reliability.md lists what is guaranteed.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path

import pytest
from test_convert import street

from bpy_pipeline import cli
from bpy_pipeline.cli.commands import main
from bpy_pipeline.config import config_from_dict
from bpy_pipeline.dataset import Dataset
from bpy_pipeline.io import read_manifest


def snapshot(folder: Path) -> dict[str, str]:
    """{relative path: sha256} of every file under ``folder``."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


def convert(capsys, scan: Path, out: Path, *extra: str) -> tuple[int, str]:
    code = main(["convert", str(scan), "--to", "vlp16", "--out", str(out), "--formats", "semantickitti,ply", *extra])
    return code, capsys.readouterr().err


def one_line(stderr: str, fragment: str) -> None:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert "Traceback" not in stderr and len(lines) == 1 and fragment in lines[0], stderr


@pytest.fixture
def dataset(tmp_path, capsys):
    """(scan, labels, out): a converted one-frame dataset in ``out``, its inputs outside it."""
    scan, labels = street(tmp_path)
    out = tmp_path / "out"
    code, err = convert(capsys, scan, out)
    assert code == 0, err
    return scan, labels, out


def test_overwrite_removes_only_what_the_run_wrote(dataset, capsys):
    scan, _, out = dataset
    (out / "notes.txt").write_text("mine")
    (out / "ply" / "keep.txt").write_text("mine too")
    (out / "sequences" / "00" / "velodyne" / "extra.bin").write_bytes(b"mine")
    (out.parent / "elsewhere" / "empty").mkdir(parents=True)
    (out / "sequences" / "01" / "elsewhere").symlink_to(out.parent / "elsewhere")  # empty folders behind a link are not ours
    code, err = convert(capsys, scan, out, "--overwrite")
    assert code == 0, err
    assert (out.parent / "elsewhere" / "empty").is_dir() and (out / "sequences" / "01" / "elsewhere").is_symlink()
    assert (out / "notes.txt").read_text() == "mine" and (out / "ply" / "keep.txt").read_text() == "mine too"
    assert (out / "sequences" / "00" / "velodyne" / "extra.bin").read_bytes() == b"mine"
    assert (out / "ply" / "000000.ply").is_file() and len(list((out / "records").iterdir())) == 1


def test_overwrite_leaves_no_file_of_the_old_run_behind(dataset, capsys):
    scan, _, out = dataset
    code, err = main(["convert", str(scan), "--to", "vlp16", "--out", str(out), "--formats", "npy", "--overwrite"]), capsys.readouterr().err
    assert code == 0, err
    assert not (out / "ply").exists() and not (out / "sequences").exists() and not (out / "semantic-kitti.yaml").exists()
    assert (out / "npy" / "000000").is_dir()


@pytest.mark.parametrize("inside", ["scan", "labels"])
def test_convert_overwrite_refuses_inputs_inside_out(dataset, capsys, inside):
    """issue 51, 1: ``convert d2/X_points.npy --labels d2/X_labels.npy --out d2 --overwrite`` deleted both inputs."""
    scan, labels, out = dataset
    moved = {"scan": scan, "labels": labels}
    target = out / moved[inside].name
    target.write_bytes(moved[inside].read_bytes())
    moved[inside] = target
    before = snapshot(out)
    code = main(["convert", str(moved["scan"]), "--labels", str(moved["labels"]), "--label-space", "raw", "--to", "hdl32e", "--out", str(out), "--overwrite"])
    assert code == 2
    one_line(capsys.readouterr().err, f"the input {target} lies inside {out}")
    assert snapshot(out) == before


def test_run_overwrite_refuses_a_config_and_scan_inside_out(dataset, capsys):
    """issue 51, 1: ``run.py --config d/cfg.yaml --out d --overwrite`` emptied d/, scan and config included."""
    scan, _, out = dataset
    (out / "scan.npy").write_bytes(scan.read_bytes())
    config = out / "cfg.yaml"
    config.write_text(f"scene: {{builder: real_scan, path: {out / 'scan.npy'}}}\n")
    before = snapshot(out)
    code = cli.main(["run.py", "--config", str(config), "--out", str(out), "--overwrite"])
    assert code == 2
    one_line(capsys.readouterr().err, f"the input {config} lies inside {out}")
    assert snapshot(out) == before


def test_a_scene_input_inside_out_is_refused_by_the_dataset(dataset):
    """The same refusal for the API and workers, from the config alone (``scene.path``)."""
    _, _, out = dataset
    (out / "scan.npy").write_bytes(b"x")
    config = config_from_dict({**read_manifest(out)["config"], "scene": {"builder": "real_scan", "path": str(out / "scan.npy")}})
    before = snapshot(out)
    with pytest.raises(Exception, match="lies inside"):
        Dataset.open(out, config, "overwrite")
    assert snapshot(out) == before


def test_a_folder_whose_manifest_is_not_ours_is_refused_not_emptied(tmp_path, capsys):
    """issue 51, 1: an unrelated ``manifest.json`` lost its folder's ``src/`` and README to ``--overwrite``."""
    scan, _ = street(tmp_path)
    web = tmp_path / "webapp"
    (web / "src").mkdir(parents=True)
    (web / "src" / "app.js").write_text("x")
    (web / "README").write_text("x")
    (web / "manifest.json").write_text('{"manifest_version": 3, "name": "x"}')
    before = snapshot(web)
    for extra in (["--overwrite"], []):
        code, err = convert(capsys, scan, web, *extra)
        assert code == 2
        one_line(err, "is not a bpy_pipeline run's manifest")
        assert snapshot(web) == before


def chattr(flag: str, path: Path) -> None:
    done = subprocess.run(["chattr", flag, str(path)], capture_output=True, check=False)
    if done.returncode:
        pytest.skip(f"chattr {flag} is not available here ({done.stderr.decode().strip()})")


def test_an_undeletable_file_refuses_before_the_first_deletion(dataset, capsys):
    """issue 51, 1: with one file immutable, ``--overwrite`` died with a traceback after deleting 150 files."""
    scan, _, out = dataset
    locked = out / "sequences" / "00" / "velodyne" / "000000.bin"
    chattr("+i", locked)
    try:
        before = snapshot(out)
        code, err = convert(capsys, scan, out, "--overwrite")
        assert code == 2
        one_line(err, f"cannot remove {locked}")
        assert snapshot(out) == before
    finally:
        chattr("-i", locked)


def test_a_crafted_intent_never_removes_a_file_outside_out(dataset, capsys):
    """issue 51, 2: ``OUT/.moving/000001.json`` naming ``../../victim/keep.txt`` and an absolute path made the
    next run delete both; the next resume or overwrite now leaves them, with one warning each."""
    scan, _, out = dataset
    victim = out.parent / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("keep")
    (victim / "keep2.txt").write_text("keep")
    (out / "ply" / "link").symlink_to(victim)  # a folder link inside OUT pointing out of it
    (out / "notes.txt").write_text("mine")  # a file of the user's inside OUT
    names = ["../victim/keep.txt", str(victim / "keep2.txt"), "ply/link/keep.txt", "ply", "\x00", "notes.txt",
             "ply/000001/../../../victim/keep.txt", "ply/link/000001.ply"]
    (victim / "000001.ply").write_text("keep")
    (out / ".moving").mkdir(exist_ok=True)
    (out / ".moving" / "000001.json").write_text(json.dumps(names))
    warnings = []
    config = config_from_dict(read_manifest(out)["config"])
    with Dataset.open(out, config, "resume", log=warnings.append):
        pass
    assert (victim / "keep.txt").read_text() == "keep" and (victim / "keep2.txt").read_text() == "keep"
    assert (victim / "000001.ply").read_text() == "keep" and (out / "notes.txt").read_text() == "mine"
    assert (out / "ply" / "000000.ply").is_file() and not (out / ".moving" / "000001.json").exists()
    assert sum("left alone" in w for w in warnings) == len(names), warnings
    (out / ".moving").mkdir(exist_ok=True)
    (out / ".moving" / "000001.json").write_text(json.dumps(names))
    code, err = convert(capsys, scan, out, "--overwrite")
    assert code == 0, err
    assert (victim / "keep.txt").read_text() == "keep" and (victim / "keep2.txt").read_text() == "keep"
    assert (victim / "000001.ply").read_text() == "keep" and (out / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("text", ["[" * 100_000 + "]" * 100_000, "[1, 2]", '{"index": "x"}', "{"])
def test_a_deep_or_strange_intent_record_or_manifest_is_one_line(dataset, text):
    """JSON nested 100,000 deep (a RecursionError in the parser), a list, a string index, a truncated object."""
    from bpy_pipeline.errors import InputError
    from bpy_pipeline.evaluate.labelled import read_generated

    _, _, out = dataset
    config = config_from_dict(read_manifest(out)["config"])
    (out / ".moving").mkdir(exist_ok=True)
    (out / ".moving" / "000002.json").write_text(text)
    (out / "records" / "000001.json").write_text(text)
    warnings = []
    with Dataset.open(out, config, "resume", log=warnings.append) as opened:
        assert opened.has(0) and not opened.has(1)
    assert any("000001.json: unreadable frame record" in w for w in warnings)
    (out / "records" / "000001.json").write_text(text)
    with pytest.raises(InputError, match="000001.json: not"):
        read_generated(out, ["car"])
    (out / "records" / "000001.json").unlink()
    (out / "manifest.json").write_text(text)
    with pytest.raises(InputError, match="manifest.json"):
        Dataset.open(out, config, "resume")


@pytest.mark.parametrize("folder", ["records", ".moving", ".staging"])
def test_a_run_folder_that_is_a_link_out_of_out_is_refused(dataset, tmp_path, folder):
    """``OUT/records`` linked to another folder would have its files removed (unreadable records) or written there."""
    _, _, out = dataset
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "000000.json").write_text("not a record")
    if (out / folder).exists():
        import shutil

        shutil.rmtree(out / folder)
    (out / folder).symlink_to(victim)
    for mode in ("resume", "overwrite"):
        with pytest.raises(Exception, match="is a link or a file, not the run's own folder"):
            Dataset.open(out, config_from_dict(read_manifest(out)["config"]), mode)
    assert (victim / "000000.json").read_text() == "not a record"


def test_a_record_naming_a_file_outside_out_is_not_read(dataset):
    """A record whose ``sha256`` names ``../x`` or ``/dev/zero`` is not read: its frame is made again."""
    _, _, out = dataset
    record = json.loads((out / "records" / "000000.json").read_text())
    crafted = [{"sha256": {name: "0" * 64}} for name in ("../../../../../../dev/zero", "/dev/zero", "ply/../../outside.bin")]
    crafted.append({"files": [*record["files"], "sequences/00/labels/../../../../outside.label"]})  # a file listed, never checked
    for change in crafted:
        (out.parent / "outside.bin").write_bytes(b"x")
        (out / "records" / "000000.json").write_text(json.dumps({**record, **change}))
        warnings = []
        with Dataset.open(out, config_from_dict(read_manifest(out)["config"]), "resume", log=warnings.append) as opened:
            assert not opened.has(0)
        assert any("does not match its record" in w for w in warnings)


def test_a_fifo_for_a_record_or_the_manifest_never_hangs(dataset, tmp_path):
    """A FIFO read as a record or a manifest would block for ever: it is refused or its frame made again."""
    import os

    from bpy_pipeline.errors import InputError

    _, _, out = dataset
    config = config_from_dict(read_manifest(out)["config"])
    os.mkfifo(out / "records" / "000001.json")
    warnings = []
    with Dataset.open(out, config, "resume", log=warnings.append) as opened:
        assert opened.has(0) and not opened.has(1)
    assert any("000001.json: unreadable frame record" in w for w in warnings)
    (out / "manifest.json").unlink()
    os.mkfifo(out / "manifest.json")
    with pytest.raises(InputError, match="not a regular file, not a run manifest"):
        Dataset.open(out, config, "resume")


# ----------------------------------------------------------------------------- paths read from an asset or a dataset
def gltf_with_buffer(folder: Path, uri: str) -> Path:
    """A .gltf box whose one buffer is the file ``uri`` (written beside it as ``box.bin`` for a good one)."""
    from test_insertion_objects import box_in_gltf, write_gltf

    folder.mkdir(parents=True, exist_ok=True)
    path = write_gltf(folder / "box.gltf", [(*box_in_gltf(1.0, 1.0, 1.0), "paint")])
    doc = json.loads(path.read_text())
    import base64

    (folder / "box.bin").write_bytes(base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1]))
    doc["buffers"][0]["uri"] = uri
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("uri, fragment", [
    ("../outside.bin", "not a relative path inside its folder"),
    ("/dev/zero", "not a relative path inside its folder"),
    ("zero", "a link pointing outside its folder"),  # a link to /dev/zero beside it
    ("fifo", "not a regular file"),
    ("out.bin", "a link pointing outside its folder"),
])
def test_a_gltf_buffer_uri_outside_its_folder_or_not_a_file_is_refused(tmp_path, uri, fragment):
    """issue 51, 2: ``buffers[].uri`` of ``../../outside.bin`` was read from outside the asset's folder; ``/dev/zero``
    read until MemoryError; a FIFO hung for ever."""
    import os

    from bpy_pipeline.errors import InputError
    from bpy_pipeline.mixing.objects import file_parts

    assets = tmp_path / "assets"
    path = gltf_with_buffer(assets, uri)
    (tmp_path / "outside.bin").write_bytes((assets / "box.bin").read_bytes())
    (assets / "zero").symlink_to("/dev/zero")
    os.mkfifo(assets / "fifo")
    (assets / "out.bin").symlink_to(tmp_path / "outside.bin")
    with pytest.raises(InputError) as info:
        file_parts(str(path))
    assert fragment in str(info.value) and "buffers[0].uri" in str(info.value) and "\n" not in str(info.value)


def test_a_gltf_buffer_beside_it_is_read(tmp_path):
    from bpy_pipeline.mixing.objects import file_parts

    parts = file_parts(str(gltf_with_buffer(tmp_path / "assets", "box.bin")))
    assert len(parts) == 1 and len(parts[0].triangles) == 12


def test_a_gltf_whose_nodes_list_the_next_twice_is_refused_at_once(tmp_path):
    """issue 51, 3: 41 nodes each listing the next one twice were walked 2**40 times."""
    import time

    from bpy_pipeline.errors import InputError
    from bpy_pipeline.mixing.objects import file_parts

    path = gltf_with_buffer(tmp_path / "assets", "box.bin")
    doc = json.loads(path.read_text())
    doc["nodes"] = [{"children": [k + 1, k + 1]} for k in range(40)] + [{"mesh": 0}]
    path.write_text(json.dumps(doc))
    start = time.perf_counter()
    with pytest.raises(InputError, match="is reached twice; a node has at most one parent"):
        file_parts(str(path))
    assert time.perf_counter() - start < 10  # exponential, it ran for hours; a generous bound, not a benchmark


def test_evaluate_never_follows_a_record_out_of_train(dataset, tmp_path):
    """issue 51, 2: a record's ``files`` entry ``ply/../../../elsewhere/000000.ply`` was read from outside ``--train``."""
    from bpy_pipeline.errors import InputError
    from bpy_pipeline.evaluate.labelled import read_generated

    _, _, out = dataset
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "000000.ply").write_bytes((out / "ply" / "000000.ply").read_bytes())
    record = json.loads((out / "records" / "000000.json").read_text())
    assert len(read_generated(out, ["car"])) == 1
    for name in ("ply/../../elsewhere/000000.ply", "ply/link.ply"):
        (out / "ply" / "link.ply").unlink(missing_ok=True)
        (out / "ply" / "link.ply").symlink_to(elsewhere / "000000.ply")
        (out / "records" / "000000.json").write_text(json.dumps({**record, "files": [name]}))
        with pytest.raises(InputError, match="a record's files lie in its dataset folder"):
            read_generated(out, ["car"])


def test_evaluate_refuses_a_class_table_that_is_a_list(dataset):
    """issue 51, 4: a manifest whose ``class_table`` is a list raised a traceback."""
    from bpy_pipeline.errors import InputError
    from bpy_pipeline.evaluate.labelled import read_generated

    _, _, out = dataset
    manifest = read_manifest(out)
    (out / "manifest.json").write_text(json.dumps({**manifest, "class_table": ["unlabeled", "car"]}))
    with pytest.raises(InputError, match="class_table must map class ids"):
        read_generated(out, ["car"])
