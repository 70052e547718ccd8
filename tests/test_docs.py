"""Docs that cannot drift unnoticed: docs/layout.md names every module of the package (and no module
that is gone), and every project file a docstring or a doc names exists.

``python tests/test_docs.py`` prints the index lines docs/layout.md lacks (a module's path and the first
line of its docstring), ready to paste into its "Every module" section.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "bpy_pipeline"
LAYOUT = ROOT / "docs" / "layout.md"
# a project path: a top-level folder of the repository (or a package below bpy_pipeline) followed by a file name
TOP = ("bpy_pipeline", "docs", "tests", "benchmarks", "scripts", "addon", "assets_manifest", "examples")
SUBPACKAGES = tuple(sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()))
PATH = re.compile(r"(?<![\w./<>{}*$-])((?:%s)/(?:[\w.-]+/)*[\w-]+\.(?:py|md|yaml|toml|sh|json))\b" % "|".join(TOP + SUBPACKAGES))
DOC = re.compile(r"(?<![\w./<>{}*$-])((?:DESIGN|README|LICENSE)\.md)\b")
SOURCES = ("bpy_pipeline", "addon", "tests", "benchmarks", "scripts", "examples")


def package_modules() -> list[str]:
    """Every module of the package as a repository path, ``bpy_pipeline/.../name.py``."""
    return sorted(str(p.relative_to(ROOT)) for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def summary(path: str) -> str:
    """The first line of a module's docstring (empty when it has none)."""
    doc = ast.get_docstring(ast.parse((ROOT / path).read_text())) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def missing_from_layout() -> list[str]:
    text = LAYOUT.read_text()
    return [m for m in package_modules() if m not in text]


def named_in_layout() -> set[str]:
    return set(re.findall(r"bpy_pipeline/[\w/]+\.py", LAYOUT.read_text()))


def exists(name: str, near: Path) -> bool:
    """``name`` (a project path) exists from the repository's root, the package or the naming file's folder."""
    return any((base / name).exists() for base in (ROOT, PACKAGE, near.parent))


def docstrings(path: Path):
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            text = ast.get_docstring(node, clean=False)
            if text:
                yield node, text


def source_files() -> list[Path]:
    """The repository's Python files (this one aside: its docstrings hold examples), without the extension's bundled copies."""
    skip = {"__pycache__", "wheels", "build"}
    out = []
    for folder in SOURCES:
        for path in (ROOT / folder).rglob("*.py"):
            parts = path.relative_to(ROOT).parts
            if skip & set(parts) or (parts[0] == "addon" and "bpy_pipeline" in parts) or path == Path(__file__).resolve():
                continue
            out.append(path)
    return sorted(out)


def dangling_names() -> list[str]:
    """``["file:line: name"]`` of project files that docstrings and docs/*.md name and that do not exist."""
    out = []
    for path in source_files():
        for node, text in docstrings(path):
            for pattern in (PATH, DOC):
                for name in pattern.findall(text):
                    if not exists(name, path):
                        out.append(f"{path.relative_to(ROOT)}:{getattr(node, 'lineno', 1)}: {name}")
    for path in sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            for pattern in (PATH, DOC):
                for name in pattern.findall(line):
                    if not exists(name, path):
                        out.append(f"{path.relative_to(ROOT)}:{number}: {name}")
    return out


def test_layout_names_every_module():
    missing = missing_from_layout()
    assert not missing, ("docs/layout.md does not name these modules (add them to its \"Every module\" section):\n"
                         + "\n".join(f"- `{m}`: {summary(m)}" for m in missing))


def test_layout_names_no_module_that_is_gone():
    gone = sorted(named_in_layout() - set(package_modules()))
    assert not gone, f"docs/layout.md names modules that do not exist: {gone}"


def test_every_file_a_docstring_or_a_doc_names_exists():
    dangling = dangling_names()
    assert not dangling, "named but absent:\n" + "\n".join(dangling)


def test_the_checks_can_fail(tmp_path):
    """The patterns find a project path, a bare DESIGN.md and a package-relative path, and skip placeholders."""
    text = "see bpy_pipeline/lidar/none.py, DESIGN.md, lidar/sensor/sensors.yaml, OUT/manifest.json, io/<format>.py and docs/*.md"
    assert PATH.findall(text) == ["bpy_pipeline/lidar/none.py", "lidar/sensor/sensors.yaml"] and DOC.findall(text) == ["DESIGN.md"]
    assert not exists("bpy_pipeline/lidar/none.py", tmp_path / "x.py") and exists("buffers.py", PACKAGE / "x.py")


if __name__ == "__main__":
    for m in missing_from_layout():
        print(f"- `{m}`: {summary(m)}")
