"""Whether the compiled passes run: the scan's, the effects' and the writers' numba kernels, or their numpy paths.

numba is optional (the ``fast`` extra); every compiled pass has a numpy path that gives the same bytes.
:data:`KERNEL_VARIABLE` set to ``numpy`` asks for those paths (tests and comparisons).
"""

from __future__ import annotations

import importlib.util
import os

KERNEL_VARIABLE = "BPY_PIPELINE_SCAN_KERNEL"  # "numpy" forces the numpy paths where no kernel is given (tests, comparisons)


def numba_available() -> bool:
    """Whether numba can be imported (without importing it)."""
    return importlib.util.find_spec("numba") is not None


def compiled_wanted() -> bool:
    """Whether the compiled passes are used: numba is importable and :data:`KERNEL_VARIABLE` does not ask for the numpy paths."""
    return os.environ.get(KERNEL_VARIABLE) != "numpy" and numba_available()
