"""Reference segmentation models over :mod:`.features`: a small registry, one entry per model.

- ``lgbm`` (default): LightGBM multiclass gradient-boosted trees (the ``evaluate`` extra: ``pip install 'bpy_pipeline[evaluate]'``);
- ``forest``: scikit-learn's random forest;
- ``rangenet``, ``rangenet-geometry``: the range-image network of :mod:`.rangenet` (the ``network`` extra, torch),
  reading remission or not.

:func:`fit` trains one on labelled scans: every point of a requested class is kept, the background ("other")
is subsampled per scan, ignored points (-1) are left out, and each class is weighted by the inverse of its
share of the sample (class-balanced), so a class of a few hundred points still counts. Fixed seed, fixed
thread count: same scans, same seed, same model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..errors import InputError
from .features import FEATURE_NAMES
from .label_maps import other_index
from .labelled import LabelledScan

MAX_POINTS_PER_SCAN = 20000  # points of each label sampled from each training scan


def _lgbm(seed: int, n_jobs: int):
    try:
        import lightgbm
    except ImportError:
        raise InputError("--model lgbm: needs LightGBM (pip install 'bpy_pipeline[evaluate]'), or use --model forest") from None
    except OSError as err:  # installed, but its library did not load: on a bare Debian, GCC's OpenMP runtime is missing
        raise InputError(f"--model lgbm: LightGBM's library did not load ({err}); on Debian: apt-get install libgomp1 (./setup.sh test does), "
                         "or use --model forest") from None
    return lightgbm.LGBMClassifier(
        n_estimators=100, learning_rate=0.08, num_leaves=31, min_child_samples=40,
        subsample=0.8, subsample_freq=1, colsample_bytree=0.8, reg_lambda=1.0,
        random_state=seed, n_jobs=n_jobs, deterministic=True, force_row_wise=True, verbose=-1,
    )  # fmt: skip


def _forest(seed: int, n_jobs: int):
    try:
        from sklearn.ensemble import RandomForestClassifier
    except ImportError:
        raise InputError("--model forest: needs scikit-learn (pip install 'bpy_pipeline[evaluate]')") from None
    return RandomForestClassifier(n_estimators=150, min_samples_leaf=5, max_features="sqrt", random_state=seed, n_jobs=n_jobs)


ESTIMATORS: dict[str, Callable[[int, int], object]] = {"lgbm": _lgbm, "forest": _forest}


@dataclass
class Model:
    """A trained reference model.

    name : the registry name
    classes : the requested classes (labels 0..C-1; C is "other")
    estimator : the fitted classifier (scikit-learn interface)
    training_points : (C + 1,) points of each label in its training sample
    """

    name: str
    classes: tuple[str, ...]
    estimator: object
    training_points: list[int] = field(default_factory=list)

    def predict(self, scan: LabelledScan) -> np.ndarray:
        """``(n,)`` int64 predicted labels (0..C) of every point of ``scan``."""
        if len(scan) == 0:
            return np.zeros(0, np.int64)
        proba = self.estimator.predict_proba(scan.features())
        return np.asarray(self.estimator.classes_, np.int64)[np.argmax(proba, axis=1)]


def training_sample(scans: Sequence[LabelledScan], classes: Sequence[str], rng: np.random.Generator,
                    max_points_per_scan: int = MAX_POINTS_PER_SCAN) -> tuple[np.ndarray, np.ndarray]:
    """``(features (m, F) float32, labels (m,) int64)``: of each scan, at most ``max_points_per_scan`` points of each
    label (all of a smaller one: objects are usually kept whole), drawn with ``rng``. A scan that labels only some of
    the classes (``known``, a KITTI frame's boxes) gives its object points only: its "other" may be of another class."""
    other = other_index(classes)
    xs, ys = [], []
    for scan in scans:
        labels = range(other + 1) if scan.known is None or len(scan.known) == len(classes) else range(other)
        keep = []
        for label in labels:
            points = np.flatnonzero(scan.labels == label)
            if len(points) > max_points_per_scan:
                points = np.sort(rng.choice(points, max_points_per_scan, replace=False))
            keep.append(points)
        keep = np.sort(np.concatenate(keep))
        if len(keep):
            xs.append(scan.features()[keep])
            ys.append(scan.labels[keep])
    if not xs:
        return np.zeros((0, len(FEATURE_NAMES)), np.float32), np.zeros(0, np.int64)
    return np.concatenate(xs), np.concatenate(ys)


def fit(scans: Sequence[LabelledScan], classes: Sequence[str], seed: int = 0, max_points_per_scan: int = MAX_POINTS_PER_SCAN,
        model: str = "lgbm", n_jobs: int = 1, log=None, steps: int | None = None):
    """Train model ``model`` (:data:`MODELS`) on ``scans``: a :class:`Model`, or a
    :class:`~.rangenet.RangeNetModel`; ``steps``: the networks' training steps (``None``: their default, see
    :func:`~.rangenet.default_steps`; the trees take none). ``InputError`` when the training set is empty or
    holds no point of any requested class, or for ``steps`` with a tree model."""
    if model not in MODELS:
        raise InputError(f"--model: unknown model {model!r}; allowed: {', '.join(MODELS)}")
    if steps is not None and model not in NEEDS_TORCH:
        raise InputError(f"--steps: only for the networks ({', '.join(sorted(NEEDS_TORCH))}), not --model {model}")
    options = {"steps": steps} if model in NEEDS_TORCH else {}
    return MODELS[model](scans, tuple(classes), seed, max_points_per_scan, model, n_jobs, log, **options)


def fit_trees(scans: Sequence[LabelledScan], classes: Sequence[str], seed: int, max_points_per_scan: int, model: str, n_jobs: int, log=None) -> Model:
    """An :data:`ESTIMATORS` model on the geometric features of a sample of the points (module notes)."""
    classes = tuple(classes)
    if not scans:
        raise InputError("--train: the training set is empty")
    x, y = training_sample(scans, classes, np.random.default_rng(seed), max_points_per_scan)
    counts = np.bincount(y, minlength=len(classes) + 1)
    if not counts[: len(classes)].any():
        raise InputError(
            f"--train: the training scans ({', '.join(s.name for s in scans[:3])}{', ...' if len(scans) > 3 else ''}) hold no point of {', '.join(classes)}"
        )
    if counts[len(classes)] == 0:
        raise InputError(f"--train: the training scans hold no background point (labelled, none of {', '.join(classes)})")
    present = counts > 0
    weight_of = np.zeros(len(counts))
    weight_of[present] = len(y) / (present.sum() * counts[present])  # class-balanced
    estimator = ESTIMATORS[model](seed, n_jobs)
    estimator.fit(x, y, sample_weight=weight_of[y])
    return Model(model, classes, estimator, [int(c) for c in counts])


def _network(remission: bool):
    def train(scans, classes, seed, max_points_per_scan, model, n_jobs, log=None, steps=None):
        from .rangenet import fit_rangenet

        return fit_rangenet(scans, classes, seed, n_jobs, remission=remission, name=model, log=log, steps=steps)

    return train


# name -> trainer(scans, classes, seed, max_points_per_scan, name, n_jobs, log[, steps: the networks']) -> a model with predict(scan)
MODELS: dict[str, Callable[..., object]] = {"lgbm": fit_trees, "forest": fit_trees, "rangenet": _network(True), "rangenet-geometry": _network(False)}
READS_REMISSION = frozenset({"rangenet"})  # models whose input holds the scans' remission
NEEDS_TORCH = frozenset({"rangenet", "rangenet-geometry"})
