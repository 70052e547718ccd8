"""Train, val and test: which split a frame belongs to, shared by every format and index.

Consecutive frames of a run are near copies of one scene, so a split drawn frame by frame leaks
the validation set into training. Frames are therefore split by **unit**:

- ``scene``: the frames one built scene serves (a builder's layout: ``frames_per_scene`` frames in a
  row; the parking, street and hall builders draw a new layout every frame);
- ``block``: ``block`` consecutive frames (a railway built once for the whole run, a trajectory);
- ``frame``: every frame alone (leaks wherever consecutive frames share a scene);
- ``fold``: the run's units cut into ``folds`` contiguous parts (the sparse-camera thesis's 5-fold
  contiguous cross-validation); fold ``fold`` is val, the others train, none test.

For scene, block and frame, unit ``u`` takes the split at position ``u + offset`` of the **quota
sequence** of the fractions ``(train, val, test)``: position ``j`` goes to the split furthest below
its share of the first ``j + 1`` positions (ties: train, val, test), so every run of ``n``
consecutive units holds each split's share of ``n`` within two units. With 0.7 / 0.15 / 0.15 it
begins train, train, val, train, test, so val has a unit from three units on and test from five.
``offset`` is 0, or drawn from ``seed`` when one is given. The split of a frame is therefore a
pure function of its index and the resolved ``output.split`` (and, for folds, the run's frame
count): any frame range, shard, worker count or resume gives the same split, and a run that grows
keeps the split of the frames it has (folds excepted).

SemanticKITTI's sequence layout: train units go round robin to sequences 00-07, 09, 10, val to
08, test round robin to 11-21 (the stock loaders' ``split2seq``); fold ``k`` of the train folds
goes to the ``k``-th train sequence.

Pure: numpy only; the config section is duck-typed (``by train val test block folds fold seed``)
and resolved by :func:`resolve` (the builder's scene length comes from the caller).
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np

from ..errors import InputError

SPLITS = ("train", "val", "test")
TRAIN_SEQUENCES = (0, 1, 2, 3, 4, 5, 6, 7, 9, 10)  # SemanticKITTI's split, as Pointcept and mmdetection3d hard-code it
VAL_SEQUENCES = (8,)
TEST_SEQUENCES = tuple(range(11, 22))
SEQUENCES = {"train": TRAIN_SEQUENCES, "val": VAL_SEQUENCES, "test": TEST_SEQUENCES}
BY = ("auto", "scene", "block", "frame", "fold")
DEFAULT_BLOCK = 10  # frames per block when output.split.block is not given
OFFSETS = 1000  # a seed draws the quota sequence's starting position among this many
SPLIT_STREAM = 0x5B117  # the split seed's stream, used by nothing else
ONE_SCENE = 2**30  # frames per scene from which a builder counts as building one scene per run (the railway's default)
WEIGHT = 10**6  # fractions as integers, so the quota sequence is exact on every machine


def resolve(split, frames: int, scene_frames: int, val_fraction: float | None = None, where: str = "output.split"):
    """The ``output.split`` section with ``by``, ``block`` and ``fold`` resolved; ``InputError`` naming the key otherwise
    (the fields' ranges are their metadata's, checked by the schema).

    split : the section (``by`` auto | scene | block | frame | fold; ``train val test`` fractions; ``block``
        frames per block, 0: :data:`DEFAULT_BLOCK`; ``folds``; ``fold`` the val fold, -1: the last; ``seed``)
    frames : the run's frame count (folds only); scene_frames : frames one built scene serves (the builder's
        ``frames_per_scene``; :data:`ONE_SCENE` or more: one scene serves the run)
    val_fraction : the older ``output.kitti.val_fraction`` (train the rest, no test), ``None`` when not given
    Returned: ``by`` scene | block | frame | fold; ``block`` the frames of one unit (a fold's units are
    scenes, or frames where one scene serves the run); ``fold`` in 0 .. folds - 1.
    """
    if split.by not in BY:
        raise InputError(f"{where}.by: expected one of {', '.join(BY)}, got {split.by!r}")
    fractions = (split.train, split.val, split.test)
    if val_fraction is not None:
        given = (1.0 - float(val_fraction), float(val_fraction), 0.0)
        if not (np.allclose(fractions, given) or np.allclose(fractions, (0.7, 0.15, 0.15))):
            raise InputError(f"output.kitti.val_fraction: give the split's fractions in {where} (train, val, test) alone; both are given")
        split = dataclasses.replace(split, train=given[0], val=given[1], test=given[2])
        fractions = given
    if abs(sum(fractions) - 1.0) > 1e-6 or split.train <= 0:
        raise InputError(f"{where}: train, val and test must add up to 1 with train > 0, got {split.train} + {split.val} + {split.test}")
    several = scene_frames < ONE_SCENE  # the builder draws new scenes during a run (not only for this frame count: a resume may grow it)
    by, block, fold = split.by, int(split.block), int(split.fold)
    if by == "auto":
        by = "scene" if several else "block"
    if by == "scene":
        if not several:
            raise InputError(f"{where}.by: scene: this builder builds one scene for the whole run; use block or fold")
        if block not in (0, scene_frames):
            raise InputError(f"{where}.block: with by: scene a unit is the builder's {scene_frames} frames; give block with by: block")
        block = scene_frames
    elif by == "block":
        block = block or DEFAULT_BLOCK
    elif by == "frame":
        if block not in (0, 1):
            raise InputError(f"{where}.block: with by: frame a unit is one frame; give block with by: block")
        block = 1
    else:  # fold
        unit = scene_frames if several else 1
        if block not in (0, unit):
            raise InputError(f"{where}.block: with by: fold a unit is {'a scene' if several else 'a frame'} ({unit} frames); give block with by: block")
        block = unit
        units = -(-frames // block)
        if isinstance(split.folds, bool) or split.folds < 2 or split.folds > units:
            raise InputError(f"{where}.folds: 2 .. {max(units, 2)} (the run has {units} {'scenes' if several else 'frames'}), got {split.folds}")
        if not -split.folds <= fold < split.folds:
            raise InputError(f"{where}.fold: the val fold, 0 .. {split.folds - 1} (-1: the last), got {split.fold}")
        fold %= split.folds
    return dataclasses.replace(split, by=by, block=block, fold=fold)


class _Quota:
    """The quota sequence of one set of integer weights, extended on demand: the split of each position and
    its ordinal among the positions of that split."""

    def __init__(self, weights: tuple[int, int, int]):
        self.weights = weights
        self.total = sum(weights)
        self.counts = [0, 0, 0]
        self.kinds = bytearray()
        self.ordinals: list[int] = []

    def at(self, position: int) -> tuple[int, int]:
        while len(self.kinds) <= position:
            j = len(self.kinds) + 1
            deficits = [w * j - c * self.total if w else -(1 << 62) for w, c in zip(self.weights, self.counts)]
            kind = deficits.index(max(deficits))
            self.kinds.append(kind)
            self.ordinals.append(self.counts[kind])
            self.counts[kind] += 1
        return self.kinds[position], self.ordinals[position]


@lru_cache(maxsize=16)
def _quota(weights: tuple[int, int, int]) -> _Quota:
    return _Quota(weights)


def _offset(seed: int | None) -> int:
    return 0 if seed is None else int(np.random.default_rng([int(seed), SPLIT_STREAM]).integers(0, OFFSETS))


def assign(index: int, split, frames: int) -> tuple[str, int]:
    """``(split name, ordinal)`` of frame ``index``: its split and the ordinal of its unit among that split's units
    (resolved ``split``, see :func:`resolve`; ``frames``: the run's frame count, used by folds)."""
    unit = int(index) // int(split.block)
    if split.by == "fold":
        units = max(-(-int(frames) // int(split.block)), 1)
        fold = min(unit * split.folds // units, split.folds - 1)
        if fold == split.fold:
            return "val", 0
        return "train", fold - (fold > split.fold)
    weights = tuple(int(round(float(f) * WEIGHT)) for f in (split.train, split.val, split.test))
    offset = _offset(split.seed)
    quota = _quota(weights)
    kind, ordinal = quota.at(unit + offset)
    return SPLITS[kind], ordinal - _count_before(quota, offset, kind)  # ordinals count from the run's first unit


def _count_before(quota: _Quota, position: int, kind: int) -> int:
    """Positions of ``kind`` before ``position`` in the quota sequence."""
    if position == 0:
        return 0
    quota.at(position - 1)
    return quota.kinds[:position].count(kind)


def split_of(index: int, split, frames: int) -> str:
    """``train``, ``val`` or ``test``: the split of frame ``index`` (see :func:`assign`)."""
    return assign(index, split, frames)[0]


def split_indices(indices, split, frames: int) -> dict[str, list[int]]:
    """``{train: [...], val: [...], test: [...]}``: the sorted frame ``indices`` of each split."""
    out: dict[str, list[int]] = {name: [] for name in SPLITS}
    for i in sorted(int(i) for i in indices):
        out[split_of(i, split, frames)].append(i)
    return out


def sequence_of(index: int, split, frames: int) -> int:
    """The SemanticKITTI sequence of frame ``index``: train 00-07, 09, 10 (round robin over the train units), val 08, test 11-21."""
    name, ordinal = assign(index, split, frames)
    choices = SEQUENCES[name]
    return choices[ordinal % len(choices)]


def split_of_sequence(sequence: int) -> str:
    """The split whose stock sequences hold ``sequence`` (train for any other number)."""
    return next((name for name, numbers in SEQUENCES.items() if int(sequence) in numbers), "train")
