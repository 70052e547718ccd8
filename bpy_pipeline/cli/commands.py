"""``bpy-pipeline COMMAND ...`` (or ``python -m bpy_pipeline COMMAND ...``): the pipeline and its tools.

Commands (:data:`COMMANDS`, in the order ``--help`` lists them):

``run [--config FILE] [--out DIR] ...``
    Generate frames, as ``run.py`` does (:mod:`bpy_pipeline.cli` lists the options).
``sensors [list]``, ``sensors show NAME [--rays FILE.npy]``
    The sensor presets, one line each, or one preset's resolved fields (:mod:`.presets`).
``fit SCAN [SCAN ...] --out MODEL.yaml [--rings 32 ...]``
    Ray drop and range noise models fitted to real organised scans (:mod:`.fit`).
``config --resolved | --reference``
    The resolved config with each value's source, or every key's reference (:mod:`.show_config`).
``evaluate --train DATASET --test REAL ... --out report.json``, ``realism ...``
    A reference model trained on generated data and tested on real labelled scans; generated against real
    per class (:mod:`.evaluate`, docs/evaluate.md).
``convert SCAN [--labels FILE] --to PRESET --out DIR [--method cones|mesh|hybrid]``
    A dense real scan resampled into a sparser sensor's firings, labels carried (:mod:`.convert`).
``match REAL [REAL ...] --config BASE.yaml --out MATCHED.yaml``
    Object statistics fitted to labelled real frames, written as a builder's placement distributions
    (:mod:`.match`, docs/match.md).

A command is a :class:`~.subcommand.Command` in its own module (its name, help and ``arguments``, which sets
``func``: ``args -> exit code``) and its name in the tuple below. Bad input (``InputError``) prints one line
and exits with code 2.
"""

from __future__ import annotations

import argparse
import sys

from ..registry import Registry
from . import COMMAND as RUN
from . import OneLineParser, exit_process, guarded, standard_streams_open
from . import convert, evaluate, fit, match, presets, show_config
from .subcommand import Command

COMMANDS: Registry[Command] = Registry("command", "COMMAND")
for _command in (RUN, presets.COMMAND, fit.COMMAND, show_config.COMMAND, evaluate.EVALUATE, evaluate.REALISM, convert.COMMAND, match.COMMAND):
    COMMANDS.register(_command.name, _command)


def parser() -> argparse.ArgumentParser:
    """The ``bpy-pipeline`` parser: one subparser per registered command (errors in one line, exit code 2)."""
    p = OneLineParser(prog="bpy-pipeline", description="Synthetic labeled LiDAR point clouds: generate frames and the tools around them.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, command in COMMANDS.items():
        command.arguments(sub.add_parser(name, help=command.help, description=command.description))
    return p


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code (2 on bad input; Ctrl-C 130, SIGTERM 143)."""
    standard_streams_open()
    args = parser().parse_args(sys.argv[1:] if argv is None else argv)
    return guarded(args.func, args)


def console() -> None:
    """The ``bpy-pipeline`` script: :func:`main`, then :func:`~bpy_pipeline.cli.exit_process` (no teardown)."""
    exit_process(main())
