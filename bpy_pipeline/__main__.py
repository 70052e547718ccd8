"""``python -m bpy_pipeline COMMAND ...``: the command line of :mod:`bpy_pipeline.cli.commands`."""

from .cli.commands import console

if __name__ == "__main__":
    console()
