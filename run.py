"""One entry point: ``python run.py [args]`` and ``blender --background --python run.py -- [args]``.

Arguments: [--config FILE] [--out DIR] [--seed N] [--frames N] [--set key.path=value ...].
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bpy_pipeline.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(sys.argv))
