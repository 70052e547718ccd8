"""What a subcommand of ``bpy-pipeline`` is: its name, its help and how it adds its arguments (:class:`Command`)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class Command:
    """One subcommand: ``bpy-pipeline NAME ...``.

    name : the word after ``bpy-pipeline``
    help : its line in ``bpy-pipeline --help``
    description : the text of its own ``--help``
    arguments : adds its arguments to its parser and sets ``func`` (``args -> exit code``) as the parser's default;
        imports what it needs when called, so the command line starts without the optional extras
    """

    name: str
    help: str
    description: str
    arguments: Callable[[argparse.ArgumentParser], object]
