"""Real Blender binaries in cached Debian chroots, driven from the host (tests/blender/test_real_blender.py).

- :class:`Chroot`: a chroot of ``tests/blender/chroots.sh`` (Debian 13 with Blender 4.3, Debian
  unstable with Blender 5.x), with /proc, /dev, /dev/shm, the repository and a work folder mounted
  at the same paths as on the host, so every path means the same inside and out.
- :class:`GuiSession`: Xvfb and a Blender window in a chroot; ``xdotool`` clicks and types,
  ``import -window root`` takes screenshots, and tests/blender/gui_session.py (running inside
  Blender) answers what Blender holds.
- :func:`panel_headers`, :func:`button_rows`, :func:`sidebar_tabs`: where the sidebar's panels, buttons
  and tabs are on a screenshot (Blender's default dark theme), so clicks follow the drawn layout.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CACHE = Path(os.environ.get("BPY_PIPELINE_CHROOTS", "/var/cache/bpy_pipeline/chroots"))
SUITES = {"trixie": "Debian 13, Blender 4.3", "sid": "Debian unstable, Blender 5.x"}
PATH = "/usr/sbin:/usr/bin:/sbin:/bin"


def frame_files(out: Path) -> dict[str, str]:
    """sha256 of every file a run wrote except the run's manifest and the per-frame records (they hold timings)."""
    return {
        str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.name != "manifest.json" and p.parent.name != "records" and not p.name.startswith(".")
    }


def records(out: Path) -> list[dict]:
    """The per-frame records without their timings (what must match between Blenders)."""
    found = []
    for path in sorted((out / "records").glob("*.json")):
        record = json.loads(path.read_text())
        found.append({k: v for k, v in record.items() if not k.startswith("timings")})
    return found


def timings(record: dict) -> dict[str, float]:
    """Stage name -> seconds of a frame record (``timings_s``; ``timings`` in older records)."""
    return record.get("timings_s", record.get("timings", {}))


class Chroot:
    """One cached chroot holding a distribution Blender."""

    def __init__(self, suite: str, cache: Path = CACHE):
        self.suite, self.root = suite, cache / suite
        self.mounted: list[Path] = []

    def ready(self) -> bool:
        return (self.root / ".bpy_pipeline_ready").is_file() and (self.root / "usr/bin/blender").is_file()

    def label(self) -> str:
        return (self.root / ".bpy_pipeline_ready").read_text().strip()

    def _mount(self, args: list[str], target: Path) -> None:
        inside = self.root / str(target).lstrip("/")
        inside.mkdir(parents=True, exist_ok=True)
        if subprocess.run(["mountpoint", "-q", str(inside)]).returncode != 0:
            subprocess.run(["mount", *args, str(inside)], check=True)
            self.mounted.append(inside)

    def mount(self, *binds: Path) -> None:
        """/proc, /dev, /dev/shm and each of ``binds`` at its own path."""
        self._mount(["-t", "proc", "proc"], Path("/proc"))
        self._mount(["--bind", "/dev"], Path("/dev"))
        self._mount(["--bind", "/dev/shm"], Path("/dev/shm"))
        for path in binds:
            self._mount(["--bind", str(path)], path)

    def unmount(self) -> None:
        while self.mounted:
            subprocess.run(["umount", "-l", str(self.mounted.pop())])

    def command(self, args: list[str], env: dict | None = None) -> list[str]:
        variables = {"PATH": PATH, "LC_ALL": "C.UTF-8", **(env or {})}
        return ["chroot", str(self.root), "env", "-i", *(f"{k}={v}" for k, v in variables.items()), *map(str, args)]

    def run(self, args: list, env: dict | None = None, timeout: float = 600, cwd: Path | None = None) -> subprocess.CompletedProcess:
        command = self.command(args, env)
        if cwd is not None:  # chroot starts in /: change directory inside
            command = self.command(["sh", "-c", 'cd "$0" && exec "$@"', str(cwd), *args], env)
        return subprocess.run(command, capture_output=True, text=True, timeout=timeout)

    def popen(self, args: list, env: dict | None = None, log: Path | None = None) -> subprocess.Popen:
        out = open(log, "w") if log else subprocess.DEVNULL  # closed with the process
        return subprocess.Popen(self.command(args, env), stdout=out, stderr=subprocess.STDOUT)

    def blender(self, args: list, home: Path, timeout: float = 600, cwd: Path | None = None) -> subprocess.CompletedProcess:
        """``blender ARGS`` with its own HOME (user preferences and extensions under it)."""
        home.mkdir(parents=True, exist_ok=True)
        return self.run(["blender", *args], {"HOME": str(home)}, timeout, cwd)


# ----------------------------------------------------------------------------- reading screenshots
WIDGET = (80, 120)  # grey of buttons and number fields (84) and of a hovered one (113), default dark theme


def _grey(img: np.ndarray) -> np.ndarray:
    """(h, w) int grey of an (h, w, 3) image, -1 where the pixel is not grey (R, G, B differ)."""
    rgb = img.astype(np.int16)
    grey = rgb[..., 0].copy()
    grey[(np.abs(rgb[..., 0] - rgb[..., 1]) > 2) | (np.abs(rgb[..., 1] - rgb[..., 2]) > 2)] = -1
    return grey


def _runs(mask: np.ndarray, min_length: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` of the True runs of a 1-d mask at least ``min_length`` long."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_length]


def sidebar_tabs(img: np.ndarray, sidebar: dict) -> list[tuple[int, int]]:
    """Vertical spans (y0, y1) of the sidebar's category tabs, top to bottom (the strip at its right edge)."""
    x = sidebar["x"] + sidebar["width"] - 21
    column = _grey(img[sidebar["y"] : sidebar["y"] + sidebar["height"], x])
    tab = (column >= 26) & (column <= 56)  # inactive 29, active 48; the strip between tabs is 24
    return [(sidebar["y"] + a, sidebar["y"] + b) for a, b in _runs(tab, 15)]


def panel_headers(img: np.ndarray, sidebar: dict) -> list[int]:
    """Screen y of each top-level panel header in the sidebar, top to bottom, found by the header's
    drag grip (two rows of light dots over dark shadow pixels, near the right end of the header)."""
    x0, x1 = sidebar["x"] + sidebar["width"] - 64, sidebar["x"] + sidebar["width"] - 28
    grey = _grey(img[sidebar["y"] : sidebar["y"] + sidebar["height"], x0:x1])
    dots = (grey >= 90) & (grey <= 175)  # 4.3: four dots of 145; 5.x: anti-aliased dots of 96 to 137
    on_header = np.abs(np.median(grey, axis=1) - 61) <= 3  # the header's grey around them (a button row is 84)
    rows = np.flatnonzero((dots.sum(axis=1) >= 3) & on_header)
    headers: list[int] = []
    for y in rows.tolist():
        if headers and y - headers[-1] <= 6:
            continue
        headers.append(y)
    return [sidebar["y"] + y + 2 for y in headers]


def button_rows(img: np.ndarray, sidebar: dict, top: int, bottom: int) -> list[list[tuple[int, int, int, int]]]:
    """The rows of grey widgets (buttons, number fields) between ``top`` and ``bottom``:
    each a list of ``(x0, y0, x1, y1)`` left to right, neighbours split by their 1-pixel seams."""
    x0, x1 = sidebar["x"] + 8, sidebar["x"] + sidebar["width"] - 26
    grey = _grey(img[top:bottom, x0:x1])
    widget = (grey >= WIDGET[0]) & (grey <= WIDGET[1])
    rows = []
    for a, b in _runs(widget.sum(axis=1) >= 40, 12):
        line = widget[a + 2]  # above the labels and icons
        rows.append([(x0 + s, top + a, x0 + e, top + b) for s, e in _runs(line, 10)])
    return rows


def centre(rect: tuple[int, int, int, int]) -> tuple[int, int]:
    return (rect[0] + rect[2]) // 2, (rect[1] + rect[3]) // 2


# ----------------------------------------------------------------------------- a Blender window
class GuiSession:
    """Xvfb and one Blender window in ``chroot``; the extension installed from ``zip_path``."""

    def __init__(self, chroot: Chroot, work: Path, zip_path: Path, display: int, size=(1280, 800)):
        self.chroot, self.work, self.zip, self.size = chroot, work, zip_path, size
        self.display = f":{display}"
        self.count = 0
        self.xvfb = self.blender = None

    def start(self, timeout: float = 120) -> dict:
        self.work.mkdir(parents=True, exist_ok=True)
        width, height = self.size
        self.xvfb = self.chroot.popen(["Xvfb", self.display, "-screen", "0", f"{width}x{height}x24", "-nolisten", "tcp"], log=self.work / "xvfb.log")
        time.sleep(1.5)
        home = self.work / "home"
        env = {"DISPLAY": self.display, "HOME": str(home), "BLENDER_USER_RESOURCES": str(home / "blender")}
        args = ["blender", "--factory-startup", "-p", "0", "0", str(width), str(height), "--python-exit-code", "1",
                "--python", str(ROOT / "tests" / "blender" / "gui_session.py"), "--", str(self.zip), str(self.work)]
        self.blender = self.chroot.popen(args, env, log=self.work / "blender.log")
        ready = self.work / "ready.json"
        deadline = time.monotonic() + timeout
        while not ready.is_file():
            if self.blender.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"Blender GUI did not start: {(self.work / 'blender.log').read_text()[-2000:]}")
            time.sleep(0.3)
        state = json.loads(ready.read_text())
        if "error" in state:
            raise RuntimeError(state["error"])
        return state

    def call(self, code: str, timeout: float = 60) -> dict:
        """Run ``code`` inside Blender (names: bpy, state, context_override, reply, WORK); returns ``reply``."""
        self.count += 1
        name = f"{self.count:04d}"
        tmp = self.work / f"cmd-{name}.tmp"
        tmp.write_text(code)
        tmp.rename(self.work / f"cmd-{name}.py")
        answer = self.work / f"reply-{name}.json"
        deadline = time.monotonic() + timeout
        while not answer.is_file():
            if self.blender.poll() is not None:
                raise RuntimeError(f"Blender exited: {(self.work / 'blender.log').read_text()[-2000:]}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"Blender did not answer within {timeout} s: {code[:200]}")
            time.sleep(0.1)
        reply = json.loads(answer.read_text())
        if not reply.pop("ok"):
            raise RuntimeError(reply["error"])
        return reply

    def state(self) -> dict:
        return self.call("reply.update(state())")

    def xdo(self, *args) -> None:
        result = self.chroot.run(["xdotool", *args], {"DISPLAY": self.display}, timeout=30)
        assert result.returncode == 0, result.stderr

    def click(self, x: int, y: int, *modifiers: str) -> None:
        """A left click at (x, y) once Blender is idle (a round trip through its event loop first)."""
        self.call("pass")
        self.xdo("mousemove", x - 3, y)
        time.sleep(0.15)
        self.xdo("mousemove", x, y)  # two moves: the button under the cursor becomes the active one
        time.sleep(0.3)
        for key in modifiers:
            self.xdo("keydown", key)
            time.sleep(0.3)  # Blender reads the modifier state from its own key events
        self.xdo("mousedown", 1)
        time.sleep(0.1)
        self.xdo("mouseup", 1)
        for key in modifiers:
            time.sleep(0.2)
            self.xdo("keyup", key)
        time.sleep(0.2)

    def key(self, *keys: str, x: int | None = None, y: int | None = None) -> None:
        if x is not None:
            self.xdo("mousemove", x, y)
            time.sleep(0.2)
        self.xdo("key", *keys)

    def screenshot(self, name: str) -> tuple[np.ndarray, Path]:
        from PIL import Image

        path = self.work / f"{name}.png"
        result = self.chroot.run(["import", "-window", "root", str(path)], {"DISPLAY": self.display}, timeout=60)
        assert result.returncode == 0, result.stderr
        return np.asarray(Image.open(path).convert("RGB")), path

    def wait(self, code: str, timeout: float = 60, every: float = 0.3) -> dict:
        """Ask ``code`` until it sets ``reply["done"]`` true; returns that reply."""
        deadline = time.monotonic() + timeout
        log = self.work / "blender.log"
        errors = log.read_text(errors="replace").count("Traceback")
        while True:
            reply = self.call(code)
            if reply.get("done"):
                time.sleep(0.3)  # an operator may still fail after doing what was asked
            text = log.read_text(errors="replace")
            if text.count("Traceback") > errors:  # an operator failed: say why now, not at the timeout
                raise RuntimeError(f"Blender reported an error: {text[-3000:]}")
            if reply.get("done"):
                return reply
            if time.monotonic() > deadline:
                raise TimeoutError(f"not done within {timeout} s: {reply}; Blender's reports: {self.reports()}")
            time.sleep(every)

    def reports(self) -> str:
        """The last lines of Blender's report log (what the status bar showed: operator errors)."""
        return self.call("""
try:
    with bpy.context.temp_override(**context_override()):
        bpy.ops.ui.reports_to_textblock()
    text = bpy.data.texts.get('Recent Reports')
    reply['text'] = text.as_string()[-1500:] if text else ''
except Exception as err:
    reply['text'] = f'(no report log: {err})'
""")["text"]

    def stop(self) -> None:
        for process in (self.blender, self.xvfb):
            if process is not None and process.poll() is None:
                process.terminate()
                try:
                    process.wait(10)
                except subprocess.TimeoutExpired:
                    process.kill()
