"""Real Blender binaries (Debian 13's 4.3, Debian unstable's 5.x) against the bpy module of this venv.

Headless: ``blender --background --python-exit-code 1 --python run.py -- ...`` writes the same
frame files as ``python run.py ...`` for the default job, parking, a primitives scene and a
user's own .blend, with ``--factory-startup`` too; a bad config exits 2 with the module's one line.

GUI (Xvfb, ``xdotool``, ``import -window root``): the extension installed from its zip, the LiDAR
tab opened, Build scene, Scan (its warning about the startup cube, which it leaves out), Show
cloud (class colours on the point-cloud objects and on the screen's pixels, the legend), Generate
with progress and Esc keeping the finished frames, Tag selected, Load and Save config.

Run by tests/blender/run_lane.sh; skipped otherwise (see conftest.py).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from realblender import ROOT, GuiSession, button_rows, centre, frame_files, panel_headers, records, sidebar_tabs, timings

RUN = str(ROOT / "run.py")
PRIMITIVES = """seed: 3
scene:
  builder: primitives
  shapes:
    - {type: plane, size: [30, 30], class: ground}
    - {type: box, size: [2, 2, 2], position: [6, 0, 1], class: wall}
    - {type: plane, size: [4, 3], position: [0, 6, 1.5], rotation_deg: [90, 0, 0], class: wall, material: mirror, reflectivity: 0.9}
    - {type: sphere, size: 0.8, position: [0, -5, 1], class: person}
    - {type: cylinder, size: [0.3, 2.0], position: [-4, 3, 1], class: mast}
sensor:
  preset: vlp16
  position: [0, 0, 1.2]
effects:
  mirrors: {max_bounces: 2}
"""
COARSE = ["--set", "sensor.horizontal_resolution_deg=0.5"]
FIGURES: dict = {}


def jobs(work: Path) -> dict[str, list[str]]:
    config = work / "primitives.yaml"
    if not config.is_file():
        config.write_text(PRIMITIVES)
    return {
        "default": COARSE,
        "parking": ["--set", "scene.builder=parking", *COARSE],
        "primitives": ["--config", str(config)],
    }


def module_run(out: Path, args: list[str]) -> subprocess.CompletedProcess:
    """``python run.py`` with this venv's bpy module."""
    return subprocess.run([sys.executable, RUN, "--out", str(out), *args], capture_output=True, text=True, timeout=600, cwd=ROOT)


def blender_run(chroot, work: Path, out: Path, args: list[str], before: list[str] = ()) -> subprocess.CompletedProcess:
    return chroot.blender([*before, "--background", "--python-exit-code", "1", "--python", RUN, "--", "--out", str(out), *args], work / f"home-{chroot.suite}",
                          cwd=work)


@pytest.fixture(scope="session")
def reference(work):
    """Outputs of the bpy module (the reference every Blender must match), made once."""
    made = {}
    for name, args in jobs(work).items():
        out = work / "module" / name
        result = module_run(out, args)
        assert result.returncode == 0, result.stderr
        made[name] = out
    return made


@pytest.fixture(scope="session")
def user_blend(work):
    """A user's own .blend (made with the bpy module): a floor, a named wall, a tagged crate, a camera."""
    path = work / "mine.blend"
    script = f"""
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_plane_add(size=30)
bpy.context.active_object.name = "Floor"
bpy.ops.mesh.primitive_cube_add(size=2, location=(5, 0, 1))
bpy.context.active_object.name = "Garden wall"
bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 4, 0.5))
crate = bpy.context.active_object
crate.name = "Crate"
crate["lidar_class"] = "car"
bpy.ops.object.camera_add(location=(0, -8, 2))
bpy.ops.wm.save_as_mainfile(filepath={str(path)!r})
"""
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    config = work / "mine.yaml"
    config.write_text(f"scene: {{builder: blend, path: {path}}}\nsensor: {{preset: vlp16, position: [0, 0, 1.5]}}\n")
    out = work / "module" / "mine"
    result = module_run(out, ["--config", str(config)])
    assert result.returncode == 0, result.stderr
    return config, out


# ----------------------------------------------------------------------------- headless
@pytest.mark.parametrize("job", ["default", "parking", "primitives"])
def test_background_run_gives_the_bpy_module_bytes(chroot, work, reference, job):
    out = work / chroot.suite / job
    result = blender_run(chroot, work, out, jobs(work)[job])
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert frame_files(out) and frame_files(out) == frame_files(reference[job])
    assert records(out) == records(reference[job])
    manifest = json.loads((out / "manifest.json").read_text())
    assert chroot.label().split()[1] in json.dumps(manifest)  # the manifest names the Blender that ran


def test_background_run_with_two_workers_gives_the_bpy_module_bytes(chroot, work, reference):
    """``--workers 2`` inside a Blender: the workers are that Blender's binary (with ``--parent-pipe``: they stop when the
    run's own process ends), and their frames are the bpy module's one process's."""
    out = work / chroot.suite / "parking-workers"
    result = blender_run(chroot, work, out, [*jobs(work)["parking"], "--workers", "2"])
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert frame_files(out) and frame_files(out) == frame_files(reference["parking"])


def test_factory_startup_and_a_users_blend(chroot, work, reference, user_blend):
    out = work / chroot.suite / "factory"
    result = blender_run(chroot, work, out, jobs(work)["default"], before=["--factory-startup"])
    assert result.returncode == 0, result.stderr[-3000:]
    assert frame_files(out) == frame_files(reference["default"])
    config, module_out = user_blend
    out = work / chroot.suite / "mine"
    result = blender_run(chroot, work, out, ["--config", str(config)])
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert frame_files(out) == frame_files(module_out)
    (frame,) = records(out)
    classes = {row["name"]: row["class"] for row in frame["objects"]}
    assert classes["Garden wall"] == "wall" and classes["Crate"] == "car", classes
    # the .blend opened by Blender first (as a user double-clicks it), then run.py on it
    out = work / chroot.suite / "mine_opened"
    result = blender_run(chroot, work, out, ["--config", str(config)], before=[str(config.with_suffix(".blend"))])
    assert result.returncode == 0, result.stderr[-3000:]
    assert frame_files(out) == frame_files(module_out)


def test_bad_config_exits_2_with_the_one_line_message(chroot, work):
    bad = ["--set", "sensor.max_range=-1"]
    expected = module_run(work / "module" / "bad", bad)
    assert expected.returncode == 2
    line = expected.stderr.strip().splitlines()[-1]
    assert line.startswith("error: sensor.") and "max_range" in line
    out = work / chroot.suite / "bad"
    result = blender_run(chroot, work, out, bad)
    assert result.returncode == 2
    assert line in (result.stdout + result.stderr).splitlines()
    assert not list(out.rglob("*.ply"))


def test_a_python_error_exits_0_without_python_exit_code(chroot, work):
    """Why the README insists on --python-exit-code 1: without it Blender reports a failed script as success."""
    script = work / "fails.py"
    script.write_text("raise RuntimeError('a failing script')\n")
    home = work / f"home-{chroot.suite}"
    assert chroot.blender(["--background", "--python", str(script)], home).returncode == 0
    assert chroot.blender(["--background", "--python-exit-code", "1", "--python", str(script)], home).returncode == 1


# ----------------------------------------------------------------------------- the panel in a window
SHOTS = os.environ.get("BPY_PIPELINE_SCREENSHOTS")  # a folder: keep this run's screenshots there (docs/img)
SHOT_SUITE = os.environ.get("BPY_PIPELINE_SCREENSHOTS_OF", "sid")


def keep_shot(suite: str, path: Path, name: str, box: tuple[int, int, int, int] | None = None, width: int = 900) -> None:
    """Copy a screenshot (cropped to ``box`` (x0, y0, x1, y1), scaled to ``width`` at most, 256 colours) to $BPY_PIPELINE_SCREENSHOTS."""
    if not SHOTS or suite != SHOT_SUITE:
        return
    from PIL import Image

    image = Image.open(path).convert("RGB")
    if box is not None:
        image = image.crop(box)
    if image.width > width:
        image = image.resize((width, round(image.height * width / image.width)), Image.LANCZOS)
    Path(SHOTS).mkdir(parents=True, exist_ok=True)
    image.quantize(256, dither=Image.Dither.NONE).save(Path(SHOTS) / f"{name}.png", optimize=True)


@pytest.fixture(scope="session")
def gui(chroot, work, extension_zip):
    session = GuiSession(chroot, work / f"gui-{chroot.suite}", extension_zip, display=90 + ["trixie", "sid"].index(chroot.suite))
    try:
        state = session.start()
        yield session, state
    finally:
        session.stop()


def sidebar_box(state: dict) -> tuple[int, int, int, int]:
    s = state["sidebar"]
    return s["x"], s["y"] - 4, s["x"] + s["width"], s["y"] + s["height"]


def find_panels(session, state, attempts: int = 8):
    """A screenshot and the spans (top, bottom) of the sidebar's top-level panels, top to bottom.

    The sidebar is read until two screenshots in a row show the same panel headers (a loaded machine
    may redraw a click's result a second or more later)."""
    sidebar = state["sidebar"]
    previous = None
    for _ in range(attempts):
        session.xdo("mousemove", sidebar["x"] + 4, sidebar["y"] + sidebar["height"] - 4)  # over the sidebar: it redraws its panels
        time.sleep(0.4)
        session.xdo("mousemove", sidebar["x"] - 250, sidebar["y"] + 400)  # no button hovered or pressed
        time.sleep(0.4)
        img, path = session.screenshot("layout")
        headers = panel_headers(img, state["sidebar"])
        if headers and headers == previous:
            break
        previous = headers
    bottom = state["sidebar"]["y"] + state["sidebar"]["height"]
    boxes = [(y - 10, (headers[i + 1] - 14) if i + 1 < len(headers) else bottom) for i, y in enumerate(headers)]
    return img, path, boxes


def main_buttons(session, state):
    """The LiDAR panel's rows: [Build scene, Scan], [Show cloud], [Frames, Generate frames], [Load, Save, Reset]."""
    img, path, boxes = find_panels(session, state)
    assert boxes, "no panel in the sidebar"
    if len(boxes) > 1 and boxes[1][0] - boxes[0][0] <= 34:  # the LiDAR panel is collapsed: open it
        session.click(state["sidebar"]["x"] + 60, boxes[0][0] + 10)
        time.sleep(0.8)
        img, path, boxes = find_panels(session, state)
    rows = button_rows(img, state["sidebar"], boxes[0][0] + 20, boxes[0][1])
    assert [len(r) for r in rows[:4]] == [2, 1, 2, 3], (rows, boxes)
    return rows


def test_gui_opens_the_lidar_tab(gui):
    session, state = gui
    assert state["enabled"], "the extension did not install and enable from its zip"
    area = state["area"]
    session.click(area["x"] + 150, area["y"] + area["height"] - 120)  # dismiss the splash screen
    time.sleep(1.0)
    session.click(area["x"] + 150, area["y"] + area["height"] - 120)
    img, _ = session.screenshot("tabs")
    tabs = sidebar_tabs(img, state["sidebar"])
    assert len(tabs) >= 2, tabs
    session.click(state["sidebar"]["x"] + state["sidebar"]["width"] - 12, (tabs[-1][0] + tabs[-1][1]) // 2)  # the add-on's tab comes last
    time.sleep(1.0)
    main_buttons(session, state)
    _, path = session.screenshot("lidar_tab")
    keep_shot(session.chroot.suite, path, "panel", sidebar_box(state), width=400)


def test_gui_build_scene_scan_leaves_the_cube_out(gui, work):
    session, state = gui
    out = session.work / "out_scan"
    session.call(f"bpy.context.scene.lidar.out_dir = {str(out)!r}")
    rows = main_buttons(session, state)
    session.click(*centre(rows[0][0]))  # Build scene
    built = session.wait(
        "c = bpy.data.collections.get('LiDAR Scene'); reply['done'] = bool(c and len(c.all_objects) > 20); reply['n'] = len(c.all_objects) if c else 0",
        timeout=120,
    )
    assert built["n"] > 20
    rows = main_buttons(session, state)
    session.click(*centre(rows[0][1]))  # Scan: the startup cube is not part of the built scene, a dialog asks
    time.sleep(2.0)
    _, path = session.screenshot("scan_warning")
    keep_shot(session.chroot.suite, path, "scan_warning", (state["area"]["x"] + 250, 60, state["area"]["x"] + state["area"]["width"], 560), width=700)
    assert not (out / "records").exists() or not list((out / "records").glob("*.json")), "Scan ran without asking about the startup cube"
    started = time.monotonic()
    session.key("Return")  # the dialog's default: leave them out
    done = session.wait(f"import pathlib; r = sorted(pathlib.Path({str(out)!r}).glob('records/*.json')); reply['done'] = bool(r)", timeout=300)
    FIGURES.setdefault(session.chroot.suite, {})["gui_scan_wall_s"] = round(time.monotonic() - started, 2)
    assert done["done"]
    (record,) = records(out)
    names = {row["name"] for row in record["objects"]}
    assert "Cube" not in names and len(names) > 20
    FIGURES[session.chroot.suite]["gui_scan_timings_s"] = timings(json.loads(next((out / "records").glob("*.json")).read_text()))
    cube = session.call("reply['hide_render'] = bpy.data.objects['Cube'].hide_render")
    assert cube["hide_render"] is False  # left out of the scan, not changed
    _, path = session.screenshot("scanned")
    keep_shot(session.chroot.suite, path, "build_and_scan", width=900)


@pytest.fixture(scope="session")
def full_default(work):
    """What the panel's Build scene then Scan must write: the default config's scene built for frame 0,
    then scanned as it is (``run_frames(build=False)``), with the bpy module.

    Not ``python run.py``'s bytes: a run that builds draws the builder's random numbers from the
    frame's generator before the effects do, a scan of a scene built earlier does not.
    """
    out = work / "module" / "default_built_then_scanned"
    script = f"""
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
from bpy_pipeline import config as cfg
from bpy_pipeline.plan import run_frames
from bpy_pipeline.stages.scene import build_frame_scene
config = cfg.config_from_dict({{}})
build_frame_scene(config, 0)
for _ in run_frames(config, {str(out)!r}, build=False, mode="overwrite"):
    pass
"""
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    return out


def test_gui_scan_writes_the_bpy_module_bytes(gui, full_default):
    session, _ = gui
    out = session.work / "out_scan"
    assert frame_files(out) == frame_files(full_default)


CLOUD_CHECK = """
import numpy as np
objs = list(bpy.data.collections['LiDAR Clouds'].objects)
out = {}
for obj in objs:
    data = obj.data
    n = len(data.vertices) if obj.type == 'MESH' else len(data.points)
    col = np.empty(n * 4, np.float32); data.attributes['Col'].data.foreach_get('color', col)
    sem = np.empty(n, np.int32); data.attributes['semantic'].data.foreach_get('value', sem)
    out[obj.name] = {'type': obj.type, 'data': type(data).__name__, 'points': n, 'semantic': sem.tolist()[::97],
                     'colors': col.reshape(-1, 4)[::97].round(5).tolist(), 'object_color': list(obj.color)}
reply['clouds'] = out
reply['legend'] = [(e.name, e.class_id, e.points, [round(c, 5) for c in e.color]) for e in bpy.context.scene.lidar.legend]
"""

TOP_VIEW = """
ctx = context_override()
area, region = ctx['area'], ctx['region']
space = area.spaces.active
space.shading.type = 'SOLID'
space.shading.light = 'FLAT'
space.shading.color_type = 'OBJECT'
bpy.context.scene.view_settings.view_transform = 'Standard'  # the screen shows the class colours unchanged (not AgX's)
space.overlay.show_floor = False
space.overlay.show_axis_x = space.overlay.show_axis_y = False
bpy.context.view_layer.layer_collection.children['LiDAR Scene'].hide_viewport = True
for obj in bpy.data.objects:
    if obj.name in ('Cube', 'Camera', 'Light'):
        obj.hide_set(True)
r3d = space.region_3d
from mathutils import Quaternion, Vector
r3d.view_perspective = 'ORTHO'
r3d.view_rotation = Quaternion((1, 0, 0, 0))
r3d.view_location = Vector((0, 0, 0))
r3d.view_distance = 18.0
area.tag_redraw()
"""


def _table():
    from bpy_pipeline.labels import load_class_table

    return load_class_table()


def _linear(rgb8: np.ndarray) -> np.ndarray:
    c = np.asarray(rgb8, np.float32) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def test_gui_show_cloud_by_class(gui):
    session, state = gui
    rows = main_buttons(session, state)
    session.click(*centre(rows[1][0]))  # Show cloud
    session.wait("c = bpy.data.collections.get('LiDAR Clouds'); reply['done'] = bool(c and c.objects)", timeout=120)
    seen = session.call(CLOUD_CHECK)
    table = _table()
    lut = table.color_lut()
    (record,) = records(session.work / "out_scan")
    assert sum(c["points"] for c in seen["clouds"].values()) == record["points"]
    direct = {n: c for n, c in seen["clouds"].items() if not n.startswith("LiDAR cloud ghosts ")}  # ghosts are paler
    for name, cloud in direct.items():  # one object per class: its name, points, colours and object colour are the class's
        (class_id,) = set(cloud["semantic"])
        assert name == f"LiDAR cloud {table.names[class_id]}"
        assert np.allclose(np.asarray(cloud["colors"])[:, :3], _linear(lut[class_id]), atol=1e-4)
        assert np.allclose(cloud["object_color"][:3], _linear(lut[class_id]), atol=1e-4)
    classes = sorted({c["semantic"][0] for c in direct.values()})
    assert len(classes) >= 4
    legend = {name: (class_id, points, color) for name, class_id, points, color in seen["legend"]}
    assert {class_id for class_id, _, _ in legend.values()} >= set(classes)
    for name, (class_id, points, color) in legend.items():
        assert table.names[class_id] == name and points > 0
        assert np.allclose(color, lut[class_id] / 255.0, atol=1e-4)  # the class table's colour (sRGB)
    # the screen: seen from above with flat lighting, points draw in their class colours
    session.call(TOP_VIEW)
    area = state["area"]
    for _ in range(6):  # a loaded machine may draw the new view a few seconds later: look again until it shows
        for dx in (0, 10):  # events make Blender redraw what the script changed
            session.xdo("mousemove", area["x"] + 300 + dx, area["y"] + 300 + dx)
            time.sleep(0.4)
        time.sleep(1.0)
        img, path = session.screenshot("cloud")
        view = img[area["y"] + 40 : area["y"] + area["height"] - 10, area["x"] + 60 : state["sidebar"]["x"] - 10].reshape(-1, 3).astype(int)
        counts = {}
        for class_id in classes:
            srgb = lut[class_id].astype(int)
            counts[table.names[class_id]] = int((np.abs(view - srgb).max(axis=1) <= 6).sum())
        shown = {name for name, n in counts.items() if n >= 20}
        if len(shown) >= 3:
            break
    assert len(shown) >= 3, counts
    FIGURES.setdefault(session.chroot.suite, {}).update(cloud_pixels_by_class=counts)
    keep_shot(session.chroot.suite, path, "show_cloud", width=900)


def test_gui_generate_shows_progress_and_esc_keeps_finished_frames(gui):
    session, state = gui
    out = session.work / "out_generate"
    session.call(f"s = bpy.context.scene.lidar; s.out_dir = {str(out)!r}; s.frames = 30")
    rows = main_buttons(session, state)
    session.click(*centre(rows[2][1]))  # Generate frames
    progress = session.wait(
        f"import pathlib; n = len(list(pathlib.Path({str(out)!r}).glob('records/*.json'))); reply.update(done=n >= 2, n=n, "
        "status=bpy.context.scene.lidar.status)",
        timeout=300,
        every=0.2,
    )
    assert progress["status"].startswith("LiDAR: ") and "/30 frames done (Esc to cancel)" in progress["status"], progress
    _, path = session.screenshot("generate_progress")
    keep_shot(session.chroot.suite, path, "generate_progress", (0, 400, state["window"]["width"], state["window"]["height"]), width=900)
    area = state["area"]
    session.key("Escape", x=area["x"] + 300, y=area["y"] + 300)
    ended = session.wait("s = bpy.context.scene.lidar.status; reply.update(done=not s.startswith('LiDAR: '), status=s)", timeout=120)
    time.sleep(3.0)  # no frame after the cancel
    frames = records(out)
    assert 2 <= len(frames) < 30, ended
    assert ended["status"].startswith(f"{len(frames)}/30 frames")
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["config"]["frames"] == 30
    assert sorted(p.name for p in (out / "ply").iterdir()) == [f"{i:06d}.ply" for i in range(len(frames))]
    assert not [p for p in out.rglob("*") if p.name.startswith(".") and p.name != ".lock"]


def test_gui_show_the_legend(gui):
    session, state = gui
    legend = session.call("reply['n'] = len(bpy.context.scene.lidar.legend)")["n"]
    assert legend > 0
    session.xdo("mousemove", state["sidebar"]["x"] - 250, state["sidebar"]["y"] + 400)
    time.sleep(0.5)
    img, path = session.screenshot("legend")
    keep_shot(session.chroot.suite, path, "legend", sidebar_box(state), width=400)
    sidebar = state["sidebar"]
    crop = img[sidebar["y"] : sidebar["y"] + sidebar["height"], sidebar["x"] : sidebar["x"] + sidebar["width"]].reshape(-1, 3).astype(int)
    table = _table()
    lut = table.color_lut()
    entries = session.call("reply['ids'] = [e.class_id for e in bpy.context.scene.lidar.legend]")["ids"]
    swatches = [int((np.abs(crop - lut[i].astype(int)).max(axis=1) <= 3).sum()) for i in entries]
    assert sum(n >= 40 for n in swatches) >= min(len(entries), 4), swatches  # each class's swatch in its table colour


def test_gui_tag_selected(gui):
    session, state = gui
    session.call("""
s = bpy.context.scene.lidar
s.label_class, s.label_material, s.label_reflectivity = 'car', 'mirror', 0.75
cube = bpy.data.objects['Cube']
cube.hide_set(False)
for o in bpy.context.view_layer.objects:
    o.select_set(False)
cube.select_set(True)
bpy.context.view_layer.objects.active = cube
""")
    img, path, boxes = find_panels(session, state)  # LiDAR, Scene, Sensor, Effects, Frames and output, Labels (last)
    tag_row = None
    for _ in range(8):  # collapse open panels above Labels (a plain click toggles one) until its buttons are on screen
        rows = button_rows(img, state["sidebar"], boxes[-1][0] + 20, boxes[-1][1])
        tag_row = next((r for r in reversed(rows) if len(r) == 2), None)
        if tag_row is not None and len(boxes) >= 6:
            break
        opened = [i for i in range(len(boxes) - 1) if boxes[i + 1][0] - boxes[i][0] > 34]
        session.click(state["sidebar"]["x"] + 60, boxes[opened[0] if opened else -1][0] + 10)
        time.sleep(0.8)
        img, path, boxes = find_panels(session, state)
    assert tag_row is not None, boxes
    session.click(*centre(tag_row[0]))  # Tag selected
    tagged = session.wait("c = bpy.data.objects['Cube']; reply.update(done='lidar_class' in c, tags={k: c[k] for k in c.keys() if k.startswith('lidar_')})",
                          timeout=30)
    assert tagged["tags"] == {"lidar_class": "car", "lidar_material": "mirror", "lidar_reflectivity": pytest.approx(0.75)}
    time.sleep(0.5)
    _, path = session.screenshot("labels")
    keep_shot(session.chroot.suite, path, "labels", sidebar_box(state), width=400)


def file_browser(session) -> dict:
    """Screen geometry of the file browser window Blender opened: its directory and file name fields."""
    reply = session.wait("""
wins = list(bpy.context.window_manager.windows)
reply['done'] = len(wins) > 1 and any(a.type == 'FILE_BROWSER' for a in wins[-1].screen.areas)
if reply['done']:
    w = wins[-1]
    a = next(a for a in w.screen.areas if a.type == 'FILE_BROWSER')
    reply['window'] = (w.x, w.y, w.width, w.height)
    reply['regions'] = {r.type: (r.x, r.y, r.width, r.height) for r in a.regions}
""", timeout=30)
    x, y, _, height = reply["window"]
    screen = session.call("reply['h'] = bpy.context.window_manager.windows[0].height")["h"]
    top = screen - (y + height)  # Blender's window y counts from the bottom of the screen

    def at(region, share):
        rx, ry, rw, rh = reply["regions"][region]
        return x + rx + int(rw * share), top + (height - (ry + rh)) + rh // 2

    return {"directory": at("UI", 0.4), "filename": at("EXECUTE", 0.3)}


def choose_file(session, path: Path) -> None:
    file_browser(session)  # wait for it
    # Blender 5.x places the file browser's window partly above the screen when no window manager runs: move it down
    session.xdo("search", "--name", "Blender File View", "windowmove", "88", "88")
    time.sleep(0.8)
    fields = file_browser(session)
    session.xdo("mousemove", *fields["directory"])
    session.xdo("click", "--repeat", 2, 1)
    time.sleep(0.4)
    session.key("ctrl+a")
    session.xdo("type", "--delay", "40", f"{path.parent}/")
    session.key("Return")
    time.sleep(0.6)
    session.xdo("mousemove", *fields["filename"])
    session.xdo("click", "--repeat", 2, 1)
    time.sleep(0.4)
    session.key("ctrl+a")
    session.xdo("type", "--delay", "40", path.name)
    session.key("Return")
    time.sleep(0.6)


def test_gui_load_and_save_config(gui, work):
    from bpy_pipeline import config as cfg

    session, state = gui
    job = jobs(work)["primitives"][1]
    rows = main_buttons(session, state)
    session.click(*centre(rows[3][0]))  # Load config
    choose_file(session, Path(job))
    session.key("Return", x=state["window"]["width"] // 2, y=state["window"]["height"] // 2)
    loaded = session.wait("s = bpy.context.scene.lidar; reply.update(done=s.status.startswith('loaded'), builder=s.builder, status=s.status)", timeout=30)
    assert loaded["builder"] == "primitives" and loaded["status"] == f"loaded {job}"
    saved = session.work / "saved.yaml"
    rows = main_buttons(session, state)
    session.click(*centre(rows[3][1]))  # Save config
    choose_file(session, saved)
    _, path = session.screenshot("save_config")
    keep_shot(session.chroot.suite, path, "save_config", width=900)
    session.key("Return", x=state["window"]["width"] // 2, y=state["window"]["height"] // 2)
    session.wait(f"import pathlib; reply['done'] = pathlib.Path({str(saved)!r}).is_file()", timeout=30)
    assert cfg.load_config(saved) == cfg.load_config(job)


# ----------------------------------------------------------------------------- figures
def test_figures_frame_time(chroot, work):
    """Seconds per frame of the default job: real Blender (background) and the bpy module, same run, same machine."""
    figures = FIGURES.setdefault(chroot.suite, {})
    frames = ["--frames", "3"]
    started = time.monotonic()
    module_out = work / "module" / "bench"
    shutil.rmtree(module_out, ignore_errors=True)
    assert module_run(module_out, frames).returncode == 0
    module_wall = time.monotonic() - started
    started = time.monotonic()
    out = work / chroot.suite / "bench"
    assert blender_run(chroot, work, out, frames).returncode == 0
    blender_wall = time.monotonic() - started

    def per_frame(folder):
        totals = [sum(timings(json.loads(p.read_text())).values()) for p in sorted((folder / "records").glob("*.json"))]
        return round(float(np.median(totals)), 3)

    figures.update(
        blender=chroot.label(),
        background_frame_s=per_frame(out),
        module_frame_s=per_frame(module_out),
        background_process_s=round(blender_wall, 2),
        module_process_s=round(module_wall, 2),
        frames=3,
    )
    figures["background_over_module"] = round(figures["background_frame_s"] / figures["module_frame_s"], 3)
    if "gui_scan_timings_s" in figures:
        figures["gui_frame_s"] = round(sum(figures["gui_scan_timings_s"].values()), 3)
        figures["gui_over_module"] = round(figures["gui_frame_s"] / figures["module_frame_s"], 3)
    target = os.environ.get("BPY_PIPELINE_REAL_BLENDER_FIGURES")
    if target:
        path = Path(target)
        existing = json.loads(path.read_text()) if path.is_file() else {}
        existing.setdefault(
            "job",
            "default job (railway, its default sensor preset, full resolution); background: 3 frames; GUI: the Scan button after Build scene (its build time "
            "is not in the frame, the scene was built before); seconds per frame = build + export + scan + write from the frame records",
        )
        existing.setdefault("blenders", {})[chroot.suite] = figures
        import bpy

        existing["module"] = f"bpy {bpy.app.version_string} (Python {sys.version.split()[0]})"
        path.write_text(json.dumps(existing, indent=1, sort_keys=True) + "\n")


# ----------------------------------------------------------------------------- Geometry Nodes groups (issue 31)
def test_node_groups_match_the_pure_functions_and_an_edited_input_rescans(chroot, work):
    """tests/blender/nodes_check.py in this Blender: groups per builder, group against pure function,
    and an input changed from Python (sag, bay width, tree density) changing the scan where it should."""
    out = work / f"nodes-{chroot.suite}.json"
    folder = work / f"nodes-{chroot.suite}"
    folder.mkdir(exist_ok=True)
    result = chroot.blender(["--background", "--factory-startup", "--python-exit-code", "1", "--python", str(ROOT / "tests" / "blender" / "nodes_check.py"),
                             "--", str(out), str(folder)],
                            work / f"home-{chroot.suite}", timeout=600)
    assert result.returncode == 0 and out.is_file(), result.stdout[-3000:] + result.stderr[-3000:]
    found = json.loads(out.read_text())
    assert "error" not in found, found["error"]
    FIGURES.setdefault(chroot.suite, {})["node_groups"] = found
    counts = found["counts"]
    assert counts["railway"]["groups"] == ["Catenary Droppers", "Catenary Wire", "Railway Supports", "Track"] and counts["railway"]["modifiers"] > 5
    assert found["railway_masts"] >= 3 and found["max_vertex_difference_m"]["railway masts"] <= 1e-5  # float32 realized: 3e-6 m measured
    assert counts["parking"]["groups"] == ["Parking Level"] and counts["parking"]["modifiers"] == 5
    assert counts["industrial_hall"]["groups"] == ["Industrial Hall"] and counts["industrial_hall"]["modifiers"] >= 3
    assert counts["street"]["groups"] == ["Street Facade", "Street Planting", "Street Road",
                                          "Street Scatter"] and counts["street"]["modifiers"] == 7 + 3 + 35 + 1  # 35 buildings, the yards
    difference = found["max_vertex_difference_m"]
    assert (
        difference["catenary wires"] <= 1e-5
        and difference["parking"] <= 1e-5
        and difference["parking doorways"] <= 1e-5
        and difference["industrial_hall"] <= 1e-5
    ), difference
    sag = found["railway_sag"]  # every contact wire 0.3 m lower at mid-span: its points lower, nothing else moved
    assert sag["edited_changed"] and sag["edited_mean_z"][1] < sag["edited_mean_z"][0] - 0.05 and sag["other_moved_over_1mm"] == 0, sag
    bays = found["parking_bay_width"]  # 2.8 m bays: the pillars moved to where the pure level with 2.8 m bays has them
    assert bays["edited_changed"] and bays["pillar_points_off_the_new_pillars_m"] <= 1e-3 and bays["other_moved_over_1mm"] == 0, bays
    assert found["street_density"]["edited_changed"], found["street_density"]
    planted = found["street_planting"]  # Density 5 trees per 100 m^2 of yard: more trunk points (none other moved: occluded ones hit the new trees)
    assert planted["edited_points"][1] > planted["edited_points"][0] and planted["other_moved_over_1mm"] == 0, planted
    lanes = found["street_lane_width"]  # every lane 1 m narrower: fewer road points, no other beam's point moved
    assert lanes["edited_changed"] and lanes["edited_points"][1] < lanes["edited_points"][0] and lanes["other_moved_over_1mm"] == 0, lanes
    assert difference["street road"] <= 1e-6 + 2.4e-5, difference  # Trim Curve's float32 arithmetic along 200 m centre lines
    assert difference["street facades"] <= 1e-5, difference


NODE_EDITOR = """
obj = next(o for o in bpy.data.objects if o.name.endswith('.contact_wire') and o.modifiers)
for o in bpy.context.view_layer.objects:
    o.select_set(False)
obj.hide_set(False)
obj.select_set(True)
bpy.context.view_layer.objects.active = obj
obj.modifiers.active = obj.modifiers[0]
area = context_override()['area']
area.ui_type = 'GeometryNodeTree'
space = area.spaces.active
if space.node_tree is None or space.node_tree.name != obj.modifiers[0].node_group.name:
    space.pin = True
    space.node_tree = obj.modifiers[0].node_group
space.show_region_ui = False
reply['tree'] = space.node_tree.name if space.node_tree else None
reply['nodes'] = len(space.node_tree.nodes) if space.node_tree else 0
"""
NODE_AREA = "window = bpy.context.window_manager.windows[0]; area = next(a for a in window.screen.areas if a.ui_type == 'GeometryNodeTree')\n"
VIEW_ALL = NODE_AREA + """region = next(r for r in area.regions if r.type == 'WINDOW')
with bpy.context.temp_override(window=window, screen=window.screen, area=area, region=region):
    bpy.ops.node.view_all()
area.tag_redraw()
"""


def built_scene(session, state) -> None:
    """The default config's scene built from the panel (Reset config, then Build scene), unless a railway is built."""
    if session.call("reply['built'] = any(o.name.endswith('.contact_wire') for o in bpy.data.objects)")["built"]:
        return
    rows = main_buttons(session, state)
    session.click(*centre(rows[3][2]))  # Reset config
    session.wait("reply['done'] = bpy.context.scene.lidar.status == 'default config'", timeout=30)
    rows = main_buttons(session, state)
    session.click(*centre(rows[0][0]))  # Build scene
    session.wait("reply['done'] = any(o.name.endswith('.contact_wire') for o in bpy.data.objects)", timeout=120)


def test_gui_node_editor_shows_the_catenary_wire_group(gui):
    session, state = gui
    built_scene(session, state)
    shown = session.call(NODE_EDITOR)
    assert shown["tree"] == "Catenary Wire" and shown["nodes"] > 10, shown
    area = state["area"]
    try:
        for call in (VIEW_ALL, VIEW_ALL):  # once the editor has drawn its region, then again for its final size
            for dx in (0, 10):  # events make Blender redraw
                session.xdo("mousemove", area["x"] + 300 + dx, area["y"] + 300 + dx)
                time.sleep(0.5)
            session.call(call)
        time.sleep(1.0)
        _, path = session.screenshot("node_editor")
        keep_shot(session.chroot.suite, path, "node_editor_catenary_wire", (area["x"], area["y"], area["x"] + area["width"], area["y"] + area["height"]),
                  width=1100)
    finally:
        session.call(NODE_AREA + "area.ui_type = 'VIEW_3D'")


SAG_EDIT = """
import importlib
compat = importlib.import_module('bl_ext.user_default.lidar_pipeline.bpy_pipeline.blender.compat')  # the installed extension's copy
get_modifier_input, set_modifier_input = compat.get_modifier_input, compat.set_modifier_input
edited = 0
for obj in bpy.data.objects:
    if obj.name.endswith('.contact_wire') and obj.modifiers:
        set_modifier_input(obj.modifiers[0], 'Sag', get_modifier_input(obj.modifiers[0], 'Sag') + 0.3)
        obj.update_tag()
        edited += 1
bpy.context.view_layer.update()
reply['edited'] = edited
"""


def test_gui_an_input_changed_from_python_then_scan_scans_the_edited_scene(gui):
    """Every contact wire's Sag 0.3 m more, set as from the Python console, then the panel's Scan: the
    contact wire's points are lower, the beams that hit anything else land where they did."""
    session, state = gui
    built_scene(session, state)
    rows = main_buttons(session, state)
    session.click(*centre(rows[3][2]))  # Reset config: the default railway job (the load test left the primitives')
    session.wait("reply['done'] = bpy.context.scene.lidar.status == 'default config'", timeout=30)
    session.call("bpy.context.scene.lidar.effects.ideal = True")  # the panel's Ideal: no noise drawn in a point order the edit changes
    clouds = {}
    for step in ("before", "after"):
        if step == "after":
            assert session.call(SAG_EDIT)["edited"] > 0
        out = session.work / f"out_rescan_{step}"
        session.call(f"bpy.context.scene.lidar.out_dir = {str(out)!r}")
        rows = main_buttons(session, state)
        session.click(*centre(rows[0][1]))  # Scan
        time.sleep(2.0)
        done = f"import pathlib; reply['done'] = bool(sorted(pathlib.Path({str(out)!r}).glob('records/*.json')))"
        if not session.call(done)["done"]:
            session.key("Return")  # the dialog about objects outside the built scene: leave them out
        session.wait(done, timeout=300)
        from bpy_pipeline.io import read_ply

        clouds[step] = read_ply(next((out / "ply").glob("*.ply")))
    wire = _table().id_of("contact wire", "lane")
    before, after = clouds["before"], clouds["after"]
    key = lambda p: {(int(r), float(t)): i for i, (r, t) in enumerate(zip(p["ring"], p["time"]))}  # noqa: E731
    a, b = key(before), key(after)
    pairs = np.array([(a[k], b[k]) for k in a.keys() & b.keys()])
    other = (before["semantic"][pairs[:, 0]] != wire) & (after["semantic"][pairs[:, 1]] != wire)
    xyz = lambda p, i: np.column_stack([p["x"][i], p["y"][i], p["z"][i]]).astype(float)  # noqa: E731
    moved = np.linalg.norm(xyz(before, pairs[other, 0]) - xyz(after, pairs[other, 1]), axis=1)
    wires = [c[c["semantic"] == wire] for c in (before, after)]
    figures = {"contact_wire_points": [len(w) for w in wires], "contact_wire_mean_z": [round(float(w["z"].mean()), 4) for w in wires],
               "other_beams": int(other.sum()), "other_moved_over_1mm": int((moved > 1e-3).sum())}
    FIGURES.setdefault(session.chroot.suite, {})["gui_edit_and_rescan"] = figures
    assert min(figures["contact_wire_points"]) > 0 and figures["contact_wire_mean_z"][1] < figures["contact_wire_mean_z"][0] - 0.05, figures
    assert figures["other_moved_over_1mm"] == 0, figures
