"""``bpy-pipeline config --resolved | --reference [--config FILE] [--set KEY.PATH=VALUE ...]``: the config as the run sees it.

``--resolved``: the resolved tree, each value with its source (:mod:`bpy_pipeline.resolved`); ``--reference``: every
config key with its type, default, unit, range and meaning (docs/config.md).
"""

from __future__ import annotations

from .subcommand import Command


def print_resolved(args) -> int:
    from ..resolved import render, resolved

    if args.reference:
        from ..config import config_reference

        print(config_reference())
        return 0

    print(render(*resolved(args.config, args.set)), end="")
    return 0


def arguments(p) -> None:
    view = p.add_mutually_exclusive_group(required=True)
    view.add_argument("--resolved", action="store_true", help="the resolved tree")
    view.add_argument("--reference", action="store_true", help="every config key with its type, default, unit, range and meaning (docs/config.md)")
    p.add_argument("--config", help="YAML config file (default: the embedded railway scene)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override one config key (repeatable)")
    p.set_defaults(func=print_resolved)


COMMAND = Command(
    "config",
    "print the resolved config with the source of each value",
    "Print the resolved config: each value with where it comes from (default < preset < builder < profile < config < --set; bpy_pipeline/resolved.py).",
    arguments,
)
