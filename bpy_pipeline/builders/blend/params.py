"""``scene.builder: blend``: the user's own .blend file, labelled by custom properties and name rules."""

from __future__ import annotations

from dataclasses import dataclass

from ...errors import InputError
from ..base import Builder, BuildContext, BuildResult, register_builder


@dataclass(frozen=True)
class BlendScene:
    """``scene.builder: blend``: scan the user's own .blend file."""

    path: str = ""



def check(params: BlendScene, where: str) -> None:
    if not params.path:
        raise InputError(f"{where}.path: the blend builder needs the path of a .blend file")


def build(params: BlendScene, context: BuildContext) -> BuildResult:
    """Open the file once per run (kept while it is the current file and unchanged on disk); every frame scans it as it is."""
    from . import scene as blend

    context.kept("blend", params, lambda: blend.OpenedBlend(params))
    return BuildResult()


register_builder("blend", Builder(BlendScene, build, check))
