"""Sim-to-real evaluation: a reference segmentation model trained on generated scans, tested on real labelled scans.

Pure numpy and scipy (the models: LightGBM or scikit-learn, the ``evaluate`` extra; the range-image network: torch,
the ``network`` extra); never imports bpy.
One concept per module:

- :mod:`.labelled`: :class:`LabelledScan` and the readers (SemanticKITTI, ``.npy`` pairs, KITTI object frames, generated datasets),
- :mod:`.label_maps`: every source's label space to the evaluation classes (SemanticKITTI training names),
- :mod:`.features`: per-point geometric features,
- :mod:`.models`: the model registry, :func:`fit` and :class:`Model`,
- :mod:`.projection`: a scan as a 64-row range image (RangeNet++'s spherical projection) and back,
- :mod:`.rangenet`: the range-image encoder-decoder (``rangenet``, ``rangenet-geometry``),
- :mod:`.metrics`: IoU, bootstrap intervals over objects, per-object recall, what the false positives are,
- :mod:`.run`: :func:`evaluate` and the report's table,
- :mod:`.realism`: generated scans against real ones per class (``bpy-pipeline realism``).

docs/evaluate.md tells how to run it, why this model, and its real-trained figures.
"""

from .label_maps import EVALUATION_CLASSES, parse_classes
from .labelled import READERS, LabelledScan, load_scans
from .metrics import score
from .models import MODELS, Model, fit
from .run import evaluate, table

__all__ = ["EVALUATION_CLASSES", "LabelledScan", "MODELS", "Model", "READERS", "evaluate", "fit", "load_scans", "parse_classes", "score", "table"]
