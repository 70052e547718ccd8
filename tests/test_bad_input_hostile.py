"""The hostile cases of issue 51 beyond the output folder (tests/test_user_files.py holds those): bounds, tracebacks,
silent wrong results, wrong reasons and missing extras. Each behaves as docs/reliability.md says: one line naming the
argument, key or file, exit code 2 (or ``InputError``), nothing written; or a bounded, reported result.
"""

from __future__ import annotations

import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline import cli
from bpy_pipeline.cli.commands import main
from bpy_pipeline.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + k)}: &{chr(98 + k)} [{', '.join(['*' + chr(97 + k)] * 10)}]\n" for k in range(8)) + "scene: {builder: railway, n: *i}\n"


def one_line(stderr: str, fragment: str) -> None:
    lines = [line for line in stderr.splitlines() if line.strip() and not line.startswith("note: estimate")]
    assert "Traceback" not in stderr and len(lines) == 1 and fragment in lines[0], stderr


def refused(fragment: str, func, *args, **kwargs) -> None:
    with pytest.raises(InputError) as info:
        func(*args, **kwargs)
    assert "\n" not in str(info.value) and fragment in str(info.value), str(info.value)


def command(capsys, *argv: str) -> tuple[int, str]:
    """``bpy-pipeline ARGV`` in-process: (exit code, stderr)."""
    try:
        code = main(list(argv))
    except SystemExit as exit_:
        code = exit_.code
    return code, capsys.readouterr().err


def npy_frame(folder: Path, n: int = 2000, labels=None) -> tuple[Path, Path]:
    """An ``X_points.npy`` / ``X_labels.npy`` pair: a ring of points 10 m around the sensor, a car (id 1) in front."""
    folder.mkdir(parents=True, exist_ok=True)
    angle = np.linspace(0, 2 * np.pi, n, endpoint=False)
    points = np.column_stack([10 * np.cos(angle), 10 * np.sin(angle), np.full(n, -1.5), np.full(n, 0.3)]).astype(np.float32)
    if labels is None:
        labels = np.where(np.abs(angle - np.pi / 8) < 0.1, 1, 9).astype(np.int64)
    np.save(folder / "X_points.npy", points)
    np.save(folder / "X_labels.npy", labels)
    return folder / "X_points.npy", folder / "X_labels.npy"


# ----------------------------------------------------------------------------- 3. runaway memory and hangs
def test_a_yaml_alias_bomb_is_refused_by_every_command(tmp_path, capsys):
    """700 bytes of nine levels of x10 anchors: 1e9 values once expanded. run.py, config --resolved and match
    --config read it through the one guard and refuse it at once."""
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(ALIAS_BOMB)
    assert len(ALIAS_BOMB) < 1000
    code = cli.main(["run.py", "--config", str(bomb), "--out", str(tmp_path / "out")])
    one_line(capsys.readouterr().err, "holds more than 100,000 values (aliases expanded)")
    assert code == 2
    code, err = command(capsys, "config", "--resolved", "--config", str(bomb))
    assert code == 2
    one_line(err, "holds more than 100,000 values (aliases expanded)")
    scan, _ = npy_frame(tmp_path / "real")
    code, err = command(capsys, "match", str(scan), "--config", str(bomb), "--out", str(tmp_path / "m.yaml"))
    assert code == 2
    one_line(err, "--config: ")
    assert "aliases expanded" in err and not (tmp_path / "m.yaml").exists() and not (tmp_path / "out").exists()
    levels = ["a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"] + [f"{b}: &{b} [{', '.join(['*' + a] * 10)}]" for a, b in zip("abc", "bcd")]
    code = cli.main(["run.py", "--out", str(tmp_path / "out"), "--set", "labels={" + ", ".join(levels) + ", e: [" + ", ".join(["*d"] * 11) + "]}"])
    assert code == 2
    one_line(capsys.readouterr().err, "--set labels: holds more than 100,000 values (aliases expanded)")


def test_an_alias_bomb_loaded_by_the_caller_is_refused_by_the_api():
    """``bp.load_config(yaml.safe_load(bomb))``: the mapping shares its lists; walked path by path it is 1e9 values."""
    import yaml

    import bpy_pipeline as bp

    refused("holds more than 100,000 values", bp.load_config, yaml.safe_load(ALIAS_BOMB))


def test_a_config_with_a_few_aliases_still_reads(tmp_path):
    from bpy_pipeline.config import load_config

    path = tmp_path / "ok.yaml"
    path.write_text("sensor: &s {preset: vlp16}\nframes: 2\nscene: {builder: railway}\n")
    assert load_config(path).sensor.spec.name == "vlp16"


def test_match_config_from_dev_zero_is_refused_by_the_size_guard(tmp_path, capsys):
    scan, _ = npy_frame(tmp_path / "real")
    code, err = command(capsys, "match", str(scan), "--config", "/dev/zero", "--out", str(tmp_path / "m.yaml"))
    assert code == 2
    one_line(err, "--config: /dev/zero: larger than 16 MB")


def test_rain_at_300_mm_h_through_a_100_mrad_beam_is_estimated_and_drawn_in_bounded_memory():
    """Both inside their documented ranges: the particles go into the estimate (limits.particles, limits.seconds) and
    are drawn in passes, so the memory stays bounded (it allocated 113 M floats)."""
    from bpy_pipeline.config import load_config
    from bpy_pipeline.estimate import check_limits, estimate_run
    from bpy_pipeline.lidar.effects import weather
    from bpy_pipeline.lidar.effects.drop.threshold import threshold_model
    from bpy_pipeline.lidar.effects.apply import fitted_models

    config = load_config({"sensor": {"preset": "vlp16"}, "effects": {"weather": {"rain": {"rate": 300}, "divergence_mrad": 100}}})
    estimate = estimate_run(config)
    assert estimate.particles > 1e8 and estimate.parts["weather"] > 60  # a hundred million drops, minutes a frame
    refused("limits.particles", check_limits, estimate, load_config({"sensor": {"preset": "vlp16"},
                                                                     "effects": {"weather": {"rain": {"rate": 300}, "divergence_mrad": 100}},
                                                                     "limits": {"particles": 1e8}}))
    check_limits(estimate_run(load_config({"sensor": {"preset": "vlp16"}, "effects": {"weather": {"rain": {"rate": 10}}}})), config)
    detect = threshold_model(config.effects, fitted_models(config.effects.drop)).detection_probability
    r = np.full(400, 100.0)  # 400 returns at 100 m: about 1.7e7 drops in their cones
    medium = weather._Medium(np.ones(len(r)), r.copy(), np.zeros(len(r)), np.full(len(r), -1, np.int8), np.full(len(r), np.nan))
    tracemalloc.start()
    weather._offer_particles(medium, r, weather._rain_particles(config.effects.weather.rain), 0.1, detect, 0.0, 1, np.random.default_rng(0))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 150 * weather.PARTICLES_PER_PASS, f"{peak / 1e6:.0f} MB"  # about 60 B a particle of one pass, never all of them
    assert (medium.kind == 1).mean() > 0.9  # and the drops are there: nearly every beam returns from one


@pytest.mark.parametrize("option, fragment", [
    (["--folds", "100000"], "--folds: must lie in 0..64"),
    (["--mlp-steps", "1000000000"], "--mlp-steps: must lie in 1..100,000"),
    (["--max-gap", "100000000"], "--max-gap: must lie in 0..1,024"),
])
def test_fit_knobs_that_multiply_work_are_bounded(option, fragment, tmp_path, capsys):
    code, err = command(capsys, "fit", str(tmp_path / "never_read.bin"), "--out", str(tmp_path / "m.yaml"), *option)
    assert code == 2
    one_line(err, fragment)


# ----------------------------------------------------------------------------- 4. tracebacks
@pytest.mark.parametrize("argv, fragment", [
    (["fit", "S", "--out", "m.yaml", "--max-range", "inf"], "fit: need 0 < --min-range < --max-range, finite metres"),
    (["fit", "S", "--out", "m.yaml", "--min-range", "nan"], "fit: need 0 < --min-range < --max-range, finite metres"),
    (["fit", "S", "--out", "m.yaml", "--intensity-scale", "0"], "--intensity-scale: must be a finite number > 0"),
    (["fit", "S", "--out", "m.yaml", "--empty-radius", "nan"], "--empty-radius: must be a finite number of metres >= 0"),
    (["evaluate", "--train", "T", "--test", "T", "--out", "r.json", "--max-points-per-scan", "-5"], "--max-points-per-scan: expected an integer >= 1, got -5"),
    (["evaluate", "--train", "T", "--test", "T", "--out", "r.json", "--seed", "-1"], "--seed: expected an integer >= 0, got -1"),
    (["sensors", "show", "vlp16", "--rays", "."], "--rays: . must be a file path in an existing folder"),
])
def test_command_line_cases_are_one_line(argv, fragment, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = [str(tmp_path / "S") if a == "S" else a for a in argv]
    code, err = command(capsys, *argv)
    assert code == 2
    one_line(err, fragment)
    assert not (tmp_path / "r.json").exists()


def test_convert_labels_of_a_0d_array(tmp_path, capsys):
    scan, _ = npy_frame(tmp_path / "real")
    np.save(tmp_path / "zero_d.npy", np.array(5))
    code, err = command(capsys, "convert", str(scan), "--labels", str(tmp_path / "zero_d.npy"), "--to", "vlp16", "--out", str(tmp_path / "out"))
    assert code == 2
    one_line(err, "expected one integer a point, (n,) or (n, 1)")


@pytest.mark.parametrize("what", ["load_config(5)", "run(dict)", "run(out=None)", "read_ply(None)", "run(frames='0')", "run(frames=[5, -1])",
                                  "load_config(overrides=None)", "run(mode='x')", "run(log=5)", "read_las(None)", "read_dataset(None)"])
def test_api_calls_with_wrong_types_raise_input_error_and_commit_nothing(what, tmp_path):
    """``bp.run(cfg, out, frames=[5, -1])`` committed ``records/000005.json`` before it raised."""
    import bpy_pipeline as bp

    config = bp.load_config({"scene": {"builder": "primitives", "shapes": [{"type": "box"}]}, "sensor": {"preset": "vlp16"}, "frames": 6})
    out = tmp_path / "out"
    calls = {
        "load_config(5)": (lambda: bp.load_config(5), "config: expected a YAML file path or a mapping, got int"),
        "run(dict)": (lambda: bp.run({"frames": 1}, out), "config: expected a Config"),
        "run(out=None)": (lambda: bp.run(config, None), "out: expected a file or folder path"),
        "read_ply(None)": (lambda: bp.read_ply(None), "path: expected a file or folder path"),
        "run(frames='0')": (lambda: bp.run(config, out, frames="0"), "frames: expected frame indices"),
        "run(frames=[5, -1])": (lambda: bp.run(config, out, frames=[5, -1]), "frames: -1 is not a frame index of this run"),
        "load_config(overrides=None)": (lambda: bp.load_config({}, None), "overrides: expected a list"),
        "run(mode='x')": (lambda: bp.run(config, out, mode="x"), "mode: 'x' is not one of new, resume, overwrite"),
        "run(log=5)": (lambda: bp.run(config, out, log=5), "log: expected a function of one str"),
        "read_las(None)": (lambda: bp.read_las(None), "path: expected a file or folder path"),
        "read_dataset(None)": (lambda: bp.read_dataset(None), "out_dir: expected a file or folder path"),
    }
    call, fragment = calls[what]
    refused(fragment, call)
    assert not out.exists()


# ----------------------------------------------------------------------------- 5. silent wrong results
def test_uint64_labels_are_refused_not_cut(tmp_path, capsys):
    scan, _ = npy_frame(tmp_path / "real")
    np.save(tmp_path / "big.npy", np.full(2000, 2**40 + 10, np.uint64))
    code, err = command(capsys, "convert", str(scan), "--labels", str(tmp_path / "big.npy"), "--label-space", "raw", "--to", "vlp16", "--out",
                        str(tmp_path / "out"))
    assert code == 2
    one_line(err, "do not fit SemanticKITTI's uint32")


@pytest.mark.parametrize("name, preset, fragment", [
    ("kitti_hdl64e_000001.bin", "hdl32e", "has 64 rings; preset hdl32e has 32 channels"),
    ("semantickitti_seq01_000000_points.npy", "hdl32e", "has rings finer than preset hdl32e's"),
    ("semantickitti_seq01_000000_points.npy", "vlp16", "of its returns outside preset vlp16's elevations"),  # was "give --from"
    ("nuscenes_hdl32e_sweep.bin", "hdl64e", "of its returns outside preset hdl64e's elevations"),
])
def test_from_a_preset_whose_rings_are_not_the_scans_is_refused(real_scan, name, preset, fragment, tmp_path, capsys):
    code, err = command(capsys, "convert", str(real_scan(name)), "--from", preset, "--to", "vlp16", "--out", str(tmp_path / "out"))
    assert code == 2
    one_line(err, f"--from: {real_scan(name)} ")
    assert fragment in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name, preset", [("kitti_hdl64e_000001.bin", "hdl64e"), ("semantickitti_seq01_000000_points.npy", "hdl64e"),
                                          ("nuscenes_hdl32e_sweep.bin", "hdl32e")])
def test_from_the_scans_own_preset_still_converts(real_scan, name, preset, tmp_path, capsys):
    code, err = command(capsys, "convert", str(real_scan(name)), "--from", preset, "--to", "vlp16", "--out", str(tmp_path / "out"))
    assert code == 0, err


def test_divergence_has_an_upper_bound_and_the_weather_cannot_inherit_past_its_own():
    from bpy_pipeline.config import load_config

    refused("sensor.divergence.mrad: must lie in 0..100", load_config, {"sensor": {"preset": "vlp16", "divergence": {"mrad": 1e9}}})
    inherited = load_config({"sensor": {"preset": "vlp16", "divergence": {"mrad": 100}}, "effects": {"weather": {"rain": {"rate": 5}}}})
    assert inherited.effects.weather.divergence_mrad == 100


def test_match_refuses_a_report_on_the_config_it_writes(tmp_path, capsys):
    scan, _ = npy_frame(tmp_path / "real")
    base = tmp_path / "base.yaml"
    base.write_text("scene: {builder: real_scan, path: x.bin}\n")
    code, err = command(capsys, "match", str(scan), "--config", str(base), "--out", str(tmp_path / "o.yaml"), "--report", str(tmp_path / "o.yaml"))
    assert code == 2
    one_line(err, "--report: ")
    assert "is the --out file too" in err and not (tmp_path / "o.yaml").exists()


@pytest.mark.parametrize("argv", [
    ["match", "REAL", "--config", "BASE", "--out", "REAL"],
    ["match", "REAL", "--config", "BASE", "--out", "BASE"],
    ["match", "REAL", "--config", "BASE", "--out", "o.yaml", "--report", "REAL"],
    ["evaluate", "--train", "REAL", "--test", "REAL", "--out", "REAL"],
    ["fit", "REAL", "--out", "REAL"],
    ["realism", "--generated", "REAL", "--real", "REAL", "--out", "REAL"],
    ["realism", "--generated", "REAL", "--real", "REAL", "--out", "o.yaml", "--plot", "REAL"],
])
def test_a_command_never_writes_over_its_own_input(argv, tmp_path, capsys):
    scan, _ = npy_frame(tmp_path / "real")
    base = tmp_path / "base.yaml"
    base.write_text("scene: {builder: real_scan, path: x.bin}\n")
    before = {p: p.read_bytes() for p in (scan, base)}
    code, err = command(capsys, *[{"REAL": str(scan), "BASE": str(base), "o.yaml": str(tmp_path / "o.yaml")}.get(a, a) for a in argv])
    assert code == 2
    one_line(err, " is the input ")
    assert {p: p.read_bytes() for p in (scan, base)} == before and not (tmp_path / "o.yaml").exists()


def test_evaluate_reports_a_class_absent_from_training_as_not_measured(tmp_path):
    """``person 0.000 [0.000, 0.000]`` was reported as if measured when the training set held no person."""
    pytest.importorskip("lightgbm")
    from bpy_pipeline.evaluate import evaluate, table

    train, _ = npy_frame(tmp_path / "train")  # cars and road, no person
    test, _ = npy_frame(tmp_path / "test")
    warnings = []
    report = evaluate([train], [test], "car,person", seed=0, log=warnings.append)
    person = report["synthetic"]["classes"]["person"]
    assert person["measured"] is False and np.isnan(person["iou"])
    assert "person  not measured (no person point in training)" in table(report)
    assert any("no person point in --train" in w for w in warnings)
    assert report["synthetic"]["classes"]["car"].get("measured", True)


# ----------------------------------------------------------------------------- 6. wrong reasons
def test_a_scan_with_nan_rows_matches_its_own_labels(tmp_path, capsys):
    """A KITTI scan with 11 NaN points and its own labels (one a row) was refused: the NaN rows were dropped first."""
    points = np.random.default_rng(0).uniform(-20, 20, (3000, 4)).astype(np.float32)
    points[:, 2] = np.abs(points[:, 2]) * 0.05 - 1.7
    points[:, 3] = 0.3
    points[np.arange(11) * 100] = np.nan
    scan = tmp_path / "scan.bin"
    points.tofile(scan)
    labels = np.full(3000, 40, np.uint32)
    labels[:1500] = 10
    labels.tofile(tmp_path / "scan.label")
    code, err = command(capsys, "convert", str(scan), "--format", "kitti", "--labels", str(tmp_path / "scan.label"), "--from", "hdl64e", "--to", "vlp16",
                        "--out", str(tmp_path / "out"))
    assert code == 0, err
    short = tmp_path / "short.label"
    labels[:2989].tofile(short)
    code, err = command(capsys, "convert", str(scan), "--format", "kitti", "--labels", str(short), "--from", "hdl64e", "--to", "vlp16", "--out",
                        str(tmp_path / "out2"))
    assert code == 2
    one_line(err, "holds 2989 labels for the scan's 3000 points")


def test_fit_intensity_scale_zero_prints_one_line_not_numpy_warnings(tmp_path):
    result = subprocess.run([PY, "-m", "bpy_pipeline", "fit", str(tmp_path / "S.bin"), "--out", str(tmp_path / "m.yaml"), "--intensity-scale", "0"],
                            cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 2
    one_line(result.stderr, "--intensity-scale: must be a finite number > 0")


# ----------------------------------------------------------------------------- 7. optional dependencies
BLOCK = "import sys; sys.modules.update({name: None for name in ARGS}); from bpy_pipeline.cli.commands import main; sys.exit(main(sys.argv[1:]))"


@pytest.mark.parametrize("blocked, argv, fragment", [
    (["scipy"], ["match", "REAL", "--config", "BASE", "--out", "OUT"], "needs scipy, which is not installed: pip install 'bpy-pipeline[evaluate]'"),
    (["plyfile"], ["convert", "PLY", "--to", "vlp16", "--out", "OUT"], "needs plyfile, which is not installed: pip install 'bpy-pipeline[mixing]'"),
    (["laspy"], ["convert", "LAS", "--to", "vlp16", "--out", "OUT"], "reading LAS needs laspy (pip install 'bpy-pipeline[las]')"),
])
def test_a_missing_extra_is_one_line_naming_it(blocked, argv, fragment, tmp_path):
    """``match`` on .npy frames died with ModuleNotFoundError where scipy was not installed."""
    scan, _ = npy_frame(tmp_path / "real")
    base = tmp_path / "base.yaml"
    base.write_text("scene: {builder: real_scan, path: x.bin}\n")
    (tmp_path / "s.ply").write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n")
    (tmp_path / "s.las").write_bytes(b"LASF" + bytes(400))
    files = {"REAL": str(scan), "BASE": str(base), "OUT": str(tmp_path / "out.yaml"), "PLY": str(tmp_path / "s.ply"), "LAS": str(tmp_path / "s.las")}
    code = BLOCK.replace("ARGS", repr(blocked))
    result = subprocess.run([PY, "-c", code, *[files.get(a, a) for a in argv]], cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 2, result.stderr
    one_line(result.stderr, fragment)


def test_lightgbm_whose_library_does_not_load_is_one_line_naming_libgomp1(monkeypatch):
    """On a bare Debian 12 LightGBM installs but its library does not load (no GCC OpenMP runtime): importing it
    raises OSError, not ImportError, which went up as a traceback."""
    from bpy_pipeline.evaluate import models

    class NoOpenMP:  # the import of lightgbm fails the way a missing libgomp.so.1 makes it fail
        @staticmethod
        def find_spec(name, path=None, target=None):
            if name == "lightgbm":
                raise OSError("libgomp.so.1: cannot open shared object file: No such file or directory")
            return None

    monkeypatch.delitem(sys.modules, "lightgbm", raising=False)
    monkeypatch.setattr(sys, "meta_path", [NoOpenMP(), *sys.meta_path])
    with pytest.raises(InputError) as err:
        models._lgbm(0, 1)
    assert "\n" not in str(err.value) and "libgomp.so.1" in str(err.value) and "apt-get install libgomp1" in str(err.value)
