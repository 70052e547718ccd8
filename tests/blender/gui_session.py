"""Runs inside a real Blender window (under Xvfb) for tests/blender/test_real_blender.py.

``blender --factory-startup -p 0 0 W H --python-exit-code 1 --python gui_session.py -- ZIP WORK``

Installs the extension from ZIP into the user folder (``BLENDER_USER_RESOURCES``), opens the 3D
Viewport's sidebar, and then serves the test driver through files in WORK: the driver writes
``WORK/cmd-N.py`` (Python run here, in Blender's main loop, with ``bpy``, ``state`` and ``reply``
in scope) and reads ``WORK/reply-N.json``. What a user does (open the LiDAR tab, press buttons,
press Esc) the driver does with ``xdotool``; this script only reports what Blender then holds
(region geometry, objects, attributes, the status bar text) and sets up preconditions.
"""

from __future__ import annotations

import json
import sys
import traceback
from pathlib import Path

import bpy

ZIP, WORK = Path(sys.argv[-2]), Path(sys.argv[-1])
MODULE = "bl_ext.user_default.lidar_pipeline"
served: set[str] = set()


def view3d():
    """``(window, area, sidebar region)`` of the first 3D Viewport."""
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "UI")
    return window, area, region


def state() -> dict:
    """What the driver needs to click and to check: geometry in X11 pixels (origin top-left)."""
    window, area, region = view3d()
    height = window.height

    def rect(r):  # Blender's origin is bottom-left
        return {"x": r.x, "y": height - (r.y + r.height), "width": r.width, "height": r.height}

    status = next((a for a in window.screen.areas if a.type == "STATUSBAR"), None)
    return {
        "blender": bpy.app.version_string,
        "window": {"width": window.width, "height": height},
        "area": rect(area),
        "sidebar": rect(region),
        "category": getattr(region, "active_panel_category", None),
        "ui_scale": bpy.context.preferences.system.ui_scale,
        "pixel_size": bpy.context.preferences.system.pixel_size,
        "status_bar": rect(status) if status else None,
        "enabled": MODULE in bpy.context.preferences.addons,
        "objects": sorted(o.name for o in bpy.data.objects),
        "lidar_status": bpy.context.scene.lidar.status if hasattr(bpy.context.scene, "lidar") else None,
    }


def context_override() -> dict:
    window, area, region = view3d()
    return {"window": window, "screen": window.screen, "area": area, "region": region}


def serve() -> float:
    """Run each new ``cmd-N.py`` once; its ``reply`` dict goes to ``reply-N.json``."""
    for path in sorted(WORK.glob("cmd-*.py")):
        if path.name in served:
            continue
        served.add(path.name)
        scope = {"bpy": bpy, "state": state, "context_override": context_override, "reply": {}, "WORK": WORK}
        try:
            exec(compile(path.read_text(), str(path), "exec"), scope)
            out = {"ok": True, **scope["reply"]}
        except Exception:  # handed to the driver, which fails the test with it
            out = {"ok": False, "error": traceback.format_exc()}
        target = WORK / path.name.replace("cmd-", "reply-").replace(".py", ".json")
        tmp = target.with_suffix(".tmp")
        tmp.write_text(json.dumps(out, default=str))
        tmp.rename(target)
    return 0.1


def start() -> None:
    result = bpy.ops.extensions.package_install_files(filepath=str(ZIP), repo="user_default", enable_on_install=True)
    assert result == {"FINISHED"}, result
    window, area, region = view3d()
    area.spaces.active.show_region_ui = True
    (WORK / "ready.json").write_text(json.dumps(state()))
    bpy.app.timers.register(serve, first_interval=0.5, persistent=True)


def start_when_drawn() -> float | None:
    """Wait for the first window to exist (timers run before the UI is drawn at startup)."""
    if not bpy.context.window_manager.windows:
        return 0.2
    try:
        start()
    except Exception:
        (WORK / "ready.json").write_text(json.dumps({"error": traceback.format_exc()}))
    return None


bpy.app.timers.register(start_when_drawn, first_interval=1.0)
