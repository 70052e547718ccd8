"""Build the Blender extension zip(s): ``python scripts/build_extension.py [--platform P ...] [--out DIR]``.

1. Reads ``blender_manifest.toml`` and fetches the wheels it lists that are not cached yet
   (``pip download --only-binary :all: --no-deps`` for each file's own Python, ABI and platform
   tags) into ``wheels/`` (git-ignored).
2. Stages the package in ``build/extension/<id>/``: ``addon/*`` as the package root, with
   ``bpy_pipeline/``, ``assets_manifest/*.yaml``, the manifest and the wheels of the chosen
   platforms (``--platform`` narrows the manifest's ``platforms`` and ``wheels`` to them).
3. Runs Blender's own extension tool from the installed ``bpy`` wheel
   (``bpy/<version>/scripts/addons_core/bl_pkg/cli/blender_ext.py``): ``validate`` on the staged
   folder, ``build`` (``--split-platforms`` when more than one platform: one zip each), and
   ``validate`` on every zip written.

Prints the zip paths; exit code 2 with a one-line message on bad input.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "blender_manifest.toml"
IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", ".*")
# Blender platform of a wheel platform tag (the tags pip and PyPI use).
WHEEL_PLATFORMS = (
    (re.compile(r"^manylinux.*_x86_64$"), "linux-x64"),
    (re.compile(r"^manylinux.*_aarch64$"), "linux-arm64"),
    (re.compile(r"^macosx_.*_arm64$"), "macos-arm64"),
    (re.compile(r"^macosx_.*_x86_64$"), "macos-x64"),
    (re.compile(r"^win_amd64$"), "windows-x64"),
    (re.compile(r"^win_arm64$"), "windows-arm64"),
)


class BuildError(Exception):
    """A one-line reason the build cannot go on."""


def wheel_tags(filename: str) -> tuple[str, str, str, str, str]:
    """``(distribution, version, python tag, abi tag, platform tag)`` of a wheel file name."""
    parts = filename.removesuffix(".whl").split("-")
    if len(parts) not in (5, 6) or not filename.endswith(".whl"):
        raise BuildError(f"{MANIFEST.name}: wheels: {filename} is not a wheel file name")
    return parts[0], parts[1], parts[-3], parts[-2], parts[-1]


def wheel_platforms(filename: str) -> set[str]:
    """Blender platforms a wheel runs on (``{"*"}`` for a pure-Python wheel)."""
    tags = wheel_tags(filename)[4].split(".")
    if tags == ["any"]:
        return {"*"}
    return {platform for tag in tags for pattern, platform in WHEEL_PLATFORMS if pattern.match(tag)}


def fetch(filename: str, cache: Path) -> Path:
    """The cached wheel ``filename``, downloaded from the package index when absent."""
    path = cache / filename
    if path.is_file():
        return path
    cache.mkdir(parents=True, exist_ok=True)
    dist, version, python_tag, abi, platform = wheel_tags(filename)
    command = [sys.executable, "-m", "pip", "download", "--quiet", "--only-binary", ":all:", "--no-deps", "--dest", str(cache)]
    if platform != "any":
        command += ["--implementation", "cp", "--python-version", python_tag.removeprefix("cp"), "--abi", abi, "--platform", platform.split(".")[0]]
    result = subprocess.run([*command, f"{dist}=={version}"], capture_output=True, text=True)
    if result.returncode != 0 or not path.is_file():
        reason = (result.stderr.strip().splitlines() or ["pip wrote another file name"])[-1]
        raise BuildError(f"wheels: cannot fetch {filename} ({reason})")
    return path


def blender_ext_tool() -> Path:
    """``blender_ext.py`` of the installed bpy wheel."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise BuildError("bpy: Blender's Python module is not installed (pip install 'bpy==4.5.*'); --blender-ext names the tool instead")
    found = sorted(Path(spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise BuildError(f"bpy: no bl_pkg/cli/blender_ext.py under {Path(spec.origin).parent}")
    return found[-1]


def toml_list(values: list[str]) -> str:
    return "[\n" + "".join(f'  "{v}",\n' for v in values) + "]"


def staged_manifest(text: str, platforms: list[str], wheels: list[str]) -> str:
    """The manifest text with ``platforms`` and ``wheels`` narrowed to the chosen platforms."""
    for key, values in (("platforms", platforms), ("wheels", wheels)):
        text, count = re.subn(rf"^{key} = \[.*?\]", lambda _: f"{key} = {toml_list(values)}", text, count=1, flags=re.MULTILINE | re.DOTALL)
        if count != 1:
            raise BuildError(f"{MANIFEST.name}: no top-level {key} = [...] list")
    return text


def missing_wheels(wheels: list[str], platforms: list[str]) -> list[str]:
    """``"<distribution> <python tag> <platform>"`` for every binary wheel a platform lacks.

    Every distribution with a binary wheel needs one per platform and per Python tag the
    wheels name (cp311 for Blender 4.2 to 5.0, cp313 for 5.1 and newer and Debian 13's 4.3, cp314 for
    distribution Blenders on Python 3.14).
    """
    names = [Path(w).name for w in wheels]
    binary = [(wheel_tags(n)[0], wheel_tags(n)[2], wheel_platforms(n)) for n in names if wheel_platforms(n) != {"*"}]
    dists, pythons = {d for d, _, _ in binary}, {p for _, p, _ in binary}
    have = {(d, p, platform) for d, p, where in binary for platform in where}
    return [f"{d} {p} {platform}" for platform in platforms for p in sorted(pythons) for d in sorted(dists) if (d, p, platform) not in have]


def stage(manifest: dict, platforms: list[str], cache: Path, stage_root: Path) -> Path:
    """Copy what runs into ``stage_root/<id>/`` and return that folder."""
    wheels = [w for w in manifest.get("wheels", []) if wheel_platforms(Path(w).name) & {"*", *platforms}]
    missing = missing_wheels(wheels, platforms)
    if missing:
        raise BuildError(f"{MANIFEST.name}: wheels: none for {missing[0]}")
    folder = stage_root / manifest["id"]
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(ROOT / "addon", folder, ignore=IGNORE)
    shutil.copytree(ROOT / "bpy_pipeline", folder / "bpy_pipeline", ignore=IGNORE)
    (folder / "assets_manifest").mkdir()
    for path in sorted((ROOT / "assets_manifest").glob("*.yaml")):  # the class table, the robot arm, asset lists
        shutil.copy2(path, folder / "assets_manifest" / path.name)
    (folder / "wheels").mkdir()
    for wheel in wheels:
        shutil.copy2(fetch(Path(wheel).name, cache), folder / wheel)
    text = MANIFEST.read_text()
    if platforms != manifest["platforms"]:
        text = staged_manifest(text, platforms, wheels)
    (folder / MANIFEST.name).write_text(text)
    return folder


def run_tool(tool: Path, *args: str) -> str:
    result = subprocess.run([sys.executable, str(tool), *args], capture_output=True, text=True)
    if result.returncode != 0:
        lines = (result.stdout + result.stderr).strip().splitlines()
        raise BuildError(f"blender_ext {args[0]}: {lines[-1] if lines else 'failed'}")
    return result.stdout


def build(platforms: list[str] | None = None, out_dir: Path = ROOT / "dist", cache: Path = ROOT / "wheels", tool: Path | None = None) -> list[Path]:
    """Stage, validate and build; returns the zip files written into ``out_dir``."""
    manifest = tomllib.loads(MANIFEST.read_text())
    version = re.search(r'__version__ = "([^"]+)"', (ROOT / "bpy_pipeline" / "_version.py").read_text()).group(1)
    if manifest["version"] != version:
        raise BuildError(f"{MANIFEST.name}: version {manifest['version']} differs from bpy_pipeline {version}")
    platforms = list(platforms or manifest["platforms"])
    unknown = [p for p in platforms if p not in manifest["platforms"]]
    if unknown:
        raise BuildError(f"--platform {unknown[0]}: not in the manifest's platforms ({', '.join(manifest['platforms'])})")
    tool = tool or blender_ext_tool()
    folder = stage(manifest, platforms, cache, ROOT / "build" / "extension")
    run_tool(tool, "validate", str(folder))
    out_dir.mkdir(parents=True, exist_ok=True)
    split = ["--split-platforms"] if len(platforms) > 1 else []
    output = run_tool(tool, "build", "--source-dir", str(folder), "--output-dir", str(out_dir), *split)
    zips = [out_dir / name for name in re.findall(r"^building: (\S+\.zip)$", output, flags=re.MULTILINE)]
    if not zips:
        raise BuildError(f"blender_ext build: wrote no zip ({output.strip().splitlines()[-1:]})")
    for path in zips:
        run_tool(tool, "validate", str(path))
    return zips


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Build the LiDAR Pipeline Blender extension with Blender's extension tool.")
    parser.add_argument("--platform", action="append", help="a platform of the manifest (repeatable; default: all, one zip each)")
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="folder for the zip files (default: dist/)")
    parser.add_argument("--wheels", type=Path, default=ROOT / "wheels", help="wheel cache (default: wheels/)")
    parser.add_argument("--blender-ext", type=Path, help="blender_ext.py to use (default: the installed bpy wheel's)")
    args = parser.parse_args(argv)
    try:
        for path in build(args.platform, args.out.resolve(), args.wheels.resolve(), args.blender_ext):
            print(path)
    except BuildError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
