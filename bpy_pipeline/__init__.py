"""bpy_pipeline: synthetic, automatically labeled LiDAR point clouds from procedural Blender scenes and real scans.

The public API (stable names; :mod:`bpy_pipeline.api` has a runnable example):

- :func:`load_config` (a YAML file or a mapping, with ``key.path=value`` overrides),
- :func:`run` (frames of a config into a dataset folder; needs Blender's ``bpy`` module),
- :func:`scan` (meshes and a sensor to labelled point records, without Blender),
- the readers :func:`read_ply`, :func:`read_semantickitti`, :func:`read_las`, :func:`read_npy_folder`,
  :func:`read_dataset` (a run's manifest with its frames' records).

The pure part (config, geometry, lidar, io) runs anywhere; ``blender`` and ``run`` need ``bpy``.
"""

import os as _os

# One BLAS thread unless the user set another count, and only if numpy is not loaded yet. numpy's OpenBLAS
# threads spin (sched_yield) for a while after every call: a 120-frame parking run spent 15 of its 36 CPU
# seconds there, on the core the scan's and the preview's threads need. The pipeline's matrices are small,
# so one thread costs no frame time; every job's files and the goldens keep their bytes.
# Workers get the same setting from parallel.SINGLE_THREAD_ENV. docs/performance.md has the measurements.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# No transparent huge pages asked for by numpy, unless the user set NUMPY_MADVISE_HUGEPAGE, and again only
# before numpy loads. numpy marks every array of 4 MB or more MADV_HUGEPAGE; where the kernel's THP defrag is
# "madvise" (the common default), a fault in such memory may stop for a synchronous compaction when no huge page
# is free (numpy issue #31590). A default railway frame's effects took 30-114 ms so, and 30-48 ms without; its
# runs took 0.92-0.95 of the wall time then, and the same when huge pages were at hand. Bytes are the same either
# way (docs/performance.md).
_os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

from ._version import __version__
from .api import load_config, run, scan
from .io import read_dataset, read_las, read_npy_folder, read_ply, read_semantickitti

__all__ = ["load_config", "run", "scan", "read_dataset", "read_las", "read_npy_folder", "read_ply", "read_semantickitti", "__version__"]
