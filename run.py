"""One entry point: ``python run.py [args]`` and ``blender --background --python run.py -- [args]``.

Arguments: [--config FILE] [--out DIR] [--seed N] [--frames N] [--set key.path=value ...].
Installed as a package, ``bpy-pipeline run [args]`` does the same.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

SETUP = (
    "bpy_pipeline cannot start: {missing} is not installed in this Python ({python}). Set up once with "
    "`python3.11 -m venv .venv && .venv/bin/pip install -e '.[blender,test]'`, then run `.venv/bin/python run.py ...` "
    "(or `blender --background --python run.py -- ...`)."
)

if __name__ == "__main__":
    try:
        from bpy_pipeline.cli import exit_process, main
    except ModuleNotFoundError as err:  # outside the venv: one line on how to set up, not a traceback
        print(SETUP.format(missing=err.name, python=sys.executable), file=sys.stderr)
        sys.exit(2)
    exit_process(main(sys.argv))
