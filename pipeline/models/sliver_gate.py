"""The sliver gate: tell frontier targets worth a trip now from slivers best left for later.

Greedy frontier exploration loses its distance on slivers: a node a step away that sees a
few frontier cells scores well on utility per metre, yet its scan reveals little (the
shadow of a wall corner, a strip along a wall seen at a grazing angle). Most slivers are
cleared on the way later, or fall inside the cells a complete episode may leave unknown.
A planner with the gate considers first only the targets the gate calls *big* (their scan
would reveal at least `min_gain` cells); the rest only when none is.

The gate is a small network (a ReLU perceptron, 16 x 16 by default; a logistic model when
it has no hidden layer) over the logs of three counts of what a candidate node's sensor fan
(the utility ray fan at the lidar's range) reaches:

- `open_unknown`: unknown cells farther than `wall_margin` cells from every known
  obstacle, reached through cells not known occupied;
- `unknown`: all unknown cells reached that way;
- `frontier`: frontier cells reached through known-free cells.

Slivers are mostly wall: the unknown they would see lies next to walls already seen (the
inside of a wall whose face is known is never observed). So the share of open unknown
carries most of the signal, the visible frontier the rest. Fitted by `stages.fit_gate` on
greedy episodes in the training mazes and office floors (`pipeline.world.offices`), labelled with
the scan the ground truth would give. A logistic
gate fitted on mazes alone rejected real targets on office floors; fitted on both families a
logistic model must trade one for the other, the perceptron need not.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np

from pipeline.common.atomic import atomic_write_text
from pipeline.common.config import validate
from pipeline.lattice.frontier import frontier_mask
from pipeline.lattice.visibility import nested_visible_counts
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN, Lidar

FEATURES = ("open_unknown", "unknown", "frontier")


def gate_features(
    belief: np.ndarray, cells: np.ndarray, range_cells: float, wall_margin: int, frontier: np.ndarray | None = None
) -> np.ndarray:
    """(n, 3) counts of FEATURES for each candidate cell (col, row) of `cells` on `belief`;
    `frontier`: `frontier_mask(belief)` when the caller keeps it (the lattice graph does)."""
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    unknown = belief == UNKNOWN
    walls = (belief == OCCUPIED).astype(np.uint8)
    side = 2 * wall_margin + 1
    near_wall = cv2.dilate(walls, np.ones((side, side), np.uint8)).astype(bool) if wall_margin else walls.astype(bool)
    passable = ~walls.astype(bool)
    frontier = frontier_mask(belief) if frontier is None else frontier
    return nested_visible_counts(
        passable, (unknown & ~near_wall, unknown), belief == FREE, frontier, cells, range_cells
    ).astype(np.float64)


def gate_inputs(counts: np.ndarray) -> np.ndarray:
    """What the logistic model reads: log(1 + count), so that shares become differences."""
    return np.log1p(np.asarray(counts, dtype=np.float64))


class TrueGain:
    """How many cells a scan from each candidate cell would reveal that the belief lacks, on the
    ground truth: the gate's label, and the oracle gate's test (`pipeline.planners.references.oracle_bounds`).
    Scans are cached per cell for the episode; only the belief changes between calls."""

    def __init__(self, ground_truth: GroundTruthMap, protocol: Protocol):
        self.lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)
        self.scans: dict[tuple[int, int], np.ndarray] = {}  # (col, row) -> flat indices of the free cells it reveals

    def gains(self, belief: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """Per (col, row) cell: the free cells its scan reveals that are not known free in `belief`."""
        flat = belief.reshape(-1)
        return np.array([(flat[self._scan(int(col), int(row))] != FREE).sum() for col, row in cells], np.int64)

    def _scan(self, col: int, row: int) -> np.ndarray:
        if (col, row) not in self.scans:
            self.scans[col, row] = self.lidar.scan((col, row)).free
        return self.scans[col, row]


Layer = tuple[tuple[tuple[float, ...], ...], tuple[float, ...]]  # (weights: inputs x outputs, biases)


@dataclass(frozen=True)
class SliverGate:
    """A fitted gate: P(big) = sigmoid(network(log(1 + counts))) over FEATURES.

    The network is a small ReLU perceptron: `layers` of (weights, biases), the last with one
    output. With a single layer it is the logistic model (`SliverGate.logistic`).
    """

    layers: tuple[Layer, ...]
    threshold: float = 0.5  # a target passes at P(big) >= threshold
    wall_margin: int = 2  # cells: unknown this close to a known obstacle is not "open"
    min_gain: int = 50  # the label: a scan revealing at least this many cells is big
    range_cells: float = 50.0  # the fan's reach in cells: the lidar range it was fitted at

    def __post_init__(self) -> None:
        layers = tuple(
            (tuple(tuple(float(w) for w in row) for row in weights), tuple(float(b) for b in biases))
            for weights, biases in self.layers
        )
        object.__setattr__(self, "layers", layers)
        width = len(FEATURES)
        for index, (weights, biases) in enumerate(layers):
            shape_ok = len(weights) == width and all(len(row) == len(biases) for row in weights) and biases
            if not shape_ok:
                raise ValueError(f"sliver gate layer {index}: expected {width} rows of {len(biases)} weights")
            if not all(math.isfinite(v) for v in (*biases, *(w for row in weights for w in row))):
                raise ValueError(f"sliver gate layer {index}: weights and biases must be finite")
            width = len(biases)
        if not layers or width != 1:
            raise ValueError(f"a sliver gate needs layers from {len(FEATURES)} counts to one output")
        if not 0.0 < self.threshold < 1.0:
            raise ValueError(f"sliver gate threshold must be in (0, 1), got {self.threshold}")

    @classmethod
    def logistic(cls, coef: tuple[float, ...], intercept: float, **settings) -> "SliverGate":
        """The one-layer gate: P(big) = sigmoid(coef . log(1 + counts) + intercept)."""
        return cls(cast(tuple[Layer, ...], (([(c,) for c in coef], (intercept,)),)), **settings)  # tuples once made

    @cached_property
    def _arrays(self) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """The layers as numpy arrays, converted once: `probability` runs at every decision."""
        return tuple((np.asarray(weights), np.asarray(biases)) for weights, biases in self.layers)

    def probability(self, counts: np.ndarray) -> np.ndarray:
        """P(big) for rows of `gate_features` counts."""
        hidden = gate_inputs(counts).reshape(-1, len(FEATURES))
        last = len(self._arrays) - 1
        for index, (weights, biases) in enumerate(self._arrays):
            hidden = hidden @ weights + biases
            if index < last:
                hidden = np.maximum(hidden, 0.0)
        return 1.0 / (1.0 + np.exp(-hidden[:, 0]))

    def reach_cells(self, range_cells: float) -> int:
        """How far (cells, Chebyshev) from a candidate a belief change can move its counts: the
        fan's reach, the wall margin around what it reaches, and the frontier's neighbours."""
        return int(math.ceil(range_cells)) + int(round(self.wall_margin * range_cells / self.range_cells)) + 1

    def passes(
        self, belief: np.ndarray, cells: np.ndarray, range_cells: float, frontier: np.ndarray | None = None
    ) -> np.ndarray:
        """Boolean mask: which candidate cells the gate calls big, for a lidar reaching `range_cells`.

        On a map drawn at another scale (the sensor reaching k times as many cells) the fan,
        the wall margin and the counts scale with it (areas by k^2, the frontier line by k), so
        the gate decides as it would on the maps it was fitted on.
        """
        if len(cells) == 0:
            return np.zeros(0, dtype=bool)
        scale = range_cells / self.range_cells
        counts = gate_features(belief, cells, range_cells, int(round(self.wall_margin * scale)), frontier)
        if scale != 1.0:
            counts = counts / np.array([scale**2, scale**2, scale])
        return self.probability(counts) >= self.threshold


def fit_sliver_gate(
    counts: np.ndarray,
    gains: np.ndarray,
    min_gain: int,
    wall_margin: int,
    range_cells: float,
    threshold: float = 0.5,
    hidden: tuple[int, ...] = (),
    seed: int = 0,
    max_samples: int | None = None,
) -> SliverGate:
    """Fit P(gain >= min_gain) on log(1 + counts) with scikit-learn.

    `max_samples`: fit on that many samples drawn at random (by `seed`) when there are more; the
    fit's cost grows with the samples, while three features are learnt from a few 100,000 as
    well as from millions.

    No `hidden` layers: logistic regression (L2 at its default strength). Hidden layers: a ReLU
    perceptron (`fit_perceptron`), which fits one gate to maps of unlike families where a
    logistic model must trade one family for the other.
    """
    counts, gains = np.asarray(counts), np.asarray(gains)
    if max_samples is not None and len(gains) > max_samples:
        drawn = np.sort(np.random.default_rng(seed).choice(len(gains), max_samples, replace=False))
        counts, gains = counts[drawn], gains[drawn]
    labels = gains >= min_gain
    if labels.all() or not labels.any():
        raise ValueError(
            f"cannot fit the sliver gate: every one of {labels.size} samples is "
            f"{'big' if labels.any() else 'a sliver'} at min_gain {min_gain}; draw more maps"
        )
    inputs = gate_inputs(counts)
    settings: dict[str, Any] = dict(
        threshold=float(threshold), wall_margin=int(wall_margin), min_gain=int(min_gain), range_cells=float(range_cells)
    )
    if not hidden:
        from sklearn.linear_model import LogisticRegression

        model = LogisticRegression(max_iter=5000).fit(inputs, labels)
        return SliverGate.logistic(tuple(model.coef_[0]), float(model.intercept_[0]), **settings)
    layers = fit_perceptron(inputs, labels, tuple(int(h) for h in hidden), seed)
    return SliverGate(layers, **settings)


def fit_perceptron(
    inputs: np.ndarray,
    labels: np.ndarray,
    hidden: tuple[int, ...],
    seed: int = 0,
    batch_size: int = 1024,
    passes: int = 10,
    min_steps: int = 2000,
    peak_lr: float = 0.005,
) -> tuple[Layer, ...]:
    """A ReLU perceptron's layers fitted on (inputs, labels) by cross-entropy: Adam on batches of
    `batch_size` under a one-cycle learning rate peaking at `peak_lr`, for `passes` passes over the
    samples and at least `min_steps` steps.

    Big batches keep the cost of millions of samples at seconds: three inputs leave the fit
    limited by its number of steps, not by the noise of a batch. Seeded: the same samples give the same layers on one torch build.
    """
    import torch

    x = torch.as_tensor(np.asarray(inputs, np.float32))
    y = torch.as_tensor(np.asarray(labels, np.float32))
    batch = min(batch_size, len(y))
    per_pass = len(y) // batch
    steps = per_pass * max(passes, math.ceil(min_steps / per_pass))
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        widths = (x.shape[1], *hidden, 1)
        linears = [torch.nn.Linear(a, b) for a, b in zip(widths, widths[1:])]
        modules: list[torch.nn.Module] = []
        for linear in linears:
            modules += [linear, torch.nn.ReLU()]
        network = torch.nn.Sequential(*modules[:-1])
        optimizer = torch.optim.Adam(network.parameters(), lr=peak_lr)
        schedule = torch.optim.lr_scheduler.OneCycleLR(optimizer, max_lr=peak_lr, total_steps=steps)
        loss = torch.nn.BCEWithLogitsLoss()
        order = torch.empty(0, dtype=torch.long)
        for step in range(steps):
            start = (step % per_pass) * batch
            if start == 0:
                order = torch.randperm(len(y))
            rows = order[start : start + batch]
            optimizer.zero_grad()
            loss(network(x[rows])[:, 0], y[rows]).backward()
            optimizer.step()
            schedule.step()
    return tuple(
        (linear.weight.detach().double().numpy().T.tolist(), linear.bias.detach().double().numpy().tolist())
        for linear in linears
    )


def roc_auc(scores: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve: the chance a random big target scores above a random sliver."""
    from sklearn.metrics import roc_auc_score

    return float(roc_auc_score(np.asarray(labels, bool), np.asarray(scores, float)))


def save_gate(gate: SliverGate, path: str | Path, protocol: dict | None = None, **record) -> Path:
    """Write the gate as JSON, with the protocol it was fitted at and anything in `record` (metrics, data)."""
    path = Path(path)
    body = {"features": list(FEATURES), "gate": asdict(gate), "protocol": protocol, **record}
    atomic_write_text(path, json.dumps(body, indent=2) + "\n")
    return path


def load_gate(path: str | Path) -> tuple[SliverGate, dict | None]:
    """(gate, protocol it was fitted at); ValueError naming the file when it is not a sliver gate."""
    path = Path(path)
    try:
        body = json.loads(path.read_text())
        if list(body.get("features", [])) != list(FEATURES):
            raise ValueError(f"features {body.get('features')!r}, expected {list(FEATURES)}")
        values = dict(body["gate"])
        if "coef" in values:  # a logistic gate written before the gate had layers
            values["layers"] = (([(c,) for c in values.pop("coef")], (values.pop("intercept"),)),)
        return validate(SliverGate, values, "gate"), body.get("protocol")
    except (OSError, json.JSONDecodeError, KeyError, TypeError, AttributeError, ValueError) as error:
        raise ValueError(f"{path}: not a sliver gate file ({error})") from None
