"""``rangenet``: a small range-image encoder-decoder, the kind of network users of this data train.

In the line of SqueezeSeg and SalsaNext: the scan is projected to a 64 x 512 range image (:mod:`.projection`;
channels x, y, z, range, remission, return mask), a residual encoder halves it three times (32, 48, 64, 96
channels), a decoder with skip connections brings it back, and a 1 x 1 head scores every pixel; each point
takes its pixel's class (back-projection, as RangeNet++ without its k-nearest-neighbour clean-up), so the
IoU and the intervals are those of :mod:`.metrics`, as for the LightGBM model. About 0.35 M parameters.

Training: Adam (lr 2e-3, cosine decay over the run) for ``steps`` steps in batches of :data:`BATCH`; by default
:func:`default_steps`: :data:`EPOCHS` passes over the training frames, at least :data:`MIN_STEPS` steps. To
compare two training sets fairly give both the same ``steps`` (``evaluate`` trains its real reference for as
many steps as the model trained on ``--train``). Each frame is turned by a random angle about z and mirrored
left-right with probability 0.5; class-weighted cross-entropy (weight 1 / (share of pixels + 0.001), as
RangeNet++). A scan that labels only some classes (``known``: KITTI boxes) adds a
partial-label term for its "other" pixels: -log of the probability of all the classes it does not know
(they are not car, person or bicyclist, but may be road or building).

Registry entries: ``rangenet`` reads remission; ``rangenet-geometry`` has the remission channel zeroed (for
scans without remission, and to measure what remission gains). Needs torch (the ``network`` extra, CPU
build); same scans, same seed, same model: torch's seed is set and its deterministic algorithms are used,
on a fixed number of threads.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..errors import InputError
from .label_maps import other_index
from .labelled import LabelledScan
from .projection import CHANNELS, WIDTH, RangeImage, project

EPOCHS = 12
MIN_STEPS = 120
BATCH = 4
LEARNING_RATE = 2e-3
WEIGHT_EPSILON = 0.001  # class weight 1 / (pixel share + this), as RangeNet++
WIDTHS = (16, 32, 64, 96)
# fixed input scaling (x, y, z, range, remission, mask): value / scale, so all channels are about unit size
SCALE = np.array([20.0, 20.0, 2.0, 20.0, 0.5, 1.0], np.float32)


def torch_module():
    """``torch``, or ``InputError`` naming the extra to install."""
    try:
        import torch
    except ImportError:
        raise InputError("--model rangenet: needs torch (pip install 'bpy_pipeline[network]', the CPU build)") from None
    return torch


def _network(torch, in_channels: int, classes: int):
    nn = torch.nn

    class Block(nn.Module):
        """Two 3 x 3 convolutions with batch norm and a 1 x 1 shortcut."""

        def __init__(self, a: int, b: int):
            super().__init__()
            self.body = nn.Sequential(nn.Conv2d(a, b, 3, padding=1, bias=False), nn.BatchNorm2d(b), nn.LeakyReLU(0.1),
                                      nn.Conv2d(b, b, 3, padding=1, bias=False), nn.BatchNorm2d(b))
            self.skip = nn.Conv2d(a, b, 1, bias=False)
            self.act = nn.LeakyReLU(0.1)

        def forward(self, x):
            return self.act(self.body(x) + self.skip(x))

    class RangeNet(nn.Module):
        """(B, in_channels, 64, W) -> (B, classes, 64, W) logits."""

        def __init__(self):
            super().__init__()
            w = WIDTHS
            self.enc = nn.ModuleList([Block(in_channels, w[0]), Block(w[0], w[1]), Block(w[1], w[2]), Block(w[2], w[3])])
            self.dec = nn.ModuleList([Block(w[3] + w[2], w[2]), Block(w[2] + w[1], w[1]), Block(w[1] + w[0], w[0])])
            self.head = nn.Conv2d(w[0], classes, 1)
            self.pool = nn.AvgPool2d(2)
            self.up = nn.Upsample(scale_factor=2, mode="nearest")

        def forward(self, x):
            skips = []
            for i, block in enumerate(self.enc):
                x = block(x if i == 0 else self.pool(x))
                skips.append(x)
            for block, skip in zip(self.dec, reversed(skips[:-1])):
                x = block(torch.cat([self.up(x), skip], dim=1))
            return self.head(x)

    return RangeNet()


def _augment(image: np.ndarray, labels: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The range image turned about z by a whole number of columns and mirrored left-right (y -> -y) half the time."""
    width = image.shape[-1]
    shift = int(rng.integers(width))
    angle = -2 * np.pi * shift / width  # columns run against azimuth (projection: u = (1 - azimuth / pi) / 2)
    image = np.roll(image, shift, axis=-1)
    labels = np.roll(labels, shift, axis=-1)
    x, y = image[0].copy(), image[1].copy()
    image[0], image[1] = np.cos(angle) * x - np.sin(angle) * y, np.sin(angle) * x + np.cos(angle) * y
    if rng.random() < 0.5:
        image = image[..., ::-1].copy()
        labels = labels[..., ::-1].copy()
        image[1] = -image[1]
    return image, labels


@dataclass
class RangeNetModel:
    """A trained range-image network (the :class:`~.models.Model` interface: ``predict(scan)``).

    name : the registry name
    classes : the requested classes (labels 0..C-1; C is "other")
    network : the torch module (eval mode)
    remission : whether the remission channel is read
    training_points : (C + 1,) labelled pixels of each label in the training images
    seconds : training time
    threads : torch threads for predictions
    steps : training steps taken
    """

    name: str
    classes: tuple[str, ...]
    network: object
    remission: bool
    training_points: list[int] = field(default_factory=list)
    seconds: float = 0.0
    threads: int = 1
    steps: int = 0

    def predict(self, scan: LabelledScan) -> np.ndarray:
        """``(n,)`` int64 predicted labels (0..C) of every point of ``scan``: its pixel's class."""
        if len(scan) == 0:
            return np.zeros(0, np.int64)
        torch = torch_module()
        torch.set_num_threads(self.threads)
        projected = project(scan, WIDTH, self.remission)
        with torch.no_grad():
            logits = self.network(torch.from_numpy(projected.image[None] / SCALE[:, None, None]))
        return logits[0].argmax(dim=0).reshape(-1).numpy().astype(np.int64)[projected.pixel]


def _other_allowed(scan: LabelledScan, classes: Sequence[str]) -> np.ndarray:
    """``(C + 1,)`` bool: the labels an "other" point of ``scan`` may truly have (all but the classes it knows)."""
    allowed = np.ones(len(classes) + 1, bool)
    if scan.known is not None and len(scan.known) < len(classes):
        for name in scan.known:
            allowed[classes.index(name)] = False
    else:
        allowed[:] = False
        allowed[other_index(classes)] = True
    return allowed


def default_steps(n_scans: int, epochs: int | None = None) -> int:
    """Training steps for ``n_scans`` frames: ``epochs`` (``None``: :data:`EPOCHS`) passes in batches of
    :data:`BATCH`, at least :data:`MIN_STEPS`."""
    return max(MIN_STEPS, math.ceil((EPOCHS if epochs is None else epochs) * n_scans / BATCH))


def fit_rangenet(scans: Sequence[LabelledScan], classes: Sequence[str], seed: int = 0, n_jobs: int = 1, remission: bool = True,
                 name: str = "rangenet", epochs: int | None = None, log=None, steps: int | None = None) -> RangeNetModel:
    """Train the network on ``scans`` for ``steps`` steps (``None``: :func:`default_steps` of ``len(scans)`` and
    ``epochs``); module notes. ``InputError`` without torch, when ``steps`` is not an integer >= 1, or when no scan
    holds a requested class. A scan listed twice is drawn twice as often (oversampling)."""
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1):
        raise InputError(f"--steps: expected an integer >= 1, got {steps!r}")
    torch = torch_module()
    classes = tuple(classes)
    n_labels = len(classes) + 1
    if not scans:
        raise InputError("--train: the training set is empty")
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True)
    torch.set_num_threads(n_jobs)
    projected = {id(s): project(s, WIDTH, remission) for s in {id(s): s for s in scans}.values()}  # a repeated scan once
    images: list[RangeImage] = [projected[id(s)] for s in scans]
    allowed = np.stack([_other_allowed(s, classes) for s in scans])
    counts = np.bincount(np.concatenate([i.labels[i.labels >= 0] for i in images]), minlength=n_labels)[:n_labels]
    if not counts[: len(classes)].any():
        raise InputError(
            f"--train: the training scans ({', '.join(s.name for s in scans[:3])}{', ...' if len(scans) > 3 else ''}) hold no point of {', '.join(classes)}"
        )
    share = counts / max(counts.sum(), 1)
    weights = np.where(counts > 0, 1.0 / (share + WEIGHT_EPSILON), 0.0)
    weights = weights / weights[counts > 0].mean()
    network = _network(torch, len(CHANNELS), n_labels)
    steps = int(steps) if steps is not None else default_steps(len(scans), epochs)
    optimiser = torch.optim.Adam(network.parameters(), lr=LEARNING_RATE)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, steps)
    weight_t = torch.from_numpy(weights.astype(np.float32))
    allowed_t = torch.from_numpy(allowed)
    scale = torch.from_numpy(SCALE[:, None, None])
    rng = np.random.default_rng(seed)
    order: list[int] = []
    start = time.perf_counter()
    network.train()
    for step in range(steps):
        if len(order) < BATCH:
            order += list(rng.permutation(len(images)))
        batch, order = order[:BATCH], order[BATCH:]
        pairs = [_augment(images[i].image, images[i].labels, rng) for i in batch]
        x = torch.from_numpy(np.stack([p[0] for p in pairs])) / scale
        y = torch.from_numpy(np.stack([p[1] for p in pairs]))
        logp = torch.log_softmax(network(x), dim=1)  # (B, K, H, W)
        valid = y >= 0
        target = y.clamp(min=0)
        ok = torch.nn.functional.one_hot(target, n_labels).permute(0, 3, 1, 2).bool()  # (B, K, H, W)
        other = (target == n_labels - 1)[:, None]
        ok = torch.where(other, allowed_t[torch.tensor(batch)][:, :, None, None], ok)
        nll = -torch.logsumexp(logp.masked_fill(~ok, -1e4), dim=1)  # (B, H, W)
        w = weight_t[target] * valid
        loss = (nll * w).sum() / w.sum().clamp(min=1e-6)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        if log and (step % 50 == 0 or step == steps - 1):
            log(f"{name}: step {step + 1}/{steps}, loss {loss.item():.3f}, {time.perf_counter() - start:.0f} s")
    network.eval()
    return RangeNetModel(name, classes, network, remission, [int(c) for c in counts], round(time.perf_counter() - start, 2), n_jobs, steps)


def parameter_count(model: RangeNetModel) -> int:
    """Trainable parameters of the network."""
    return sum(p.numel() for p in model.network.parameters() if p.requires_grad)
