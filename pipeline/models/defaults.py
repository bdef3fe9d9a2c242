"""Where each trained model is found, and its loader: one place for every default model path.

A planner that needs a model takes the file it is given; else the one the pipeline trained
(`models/...` of pipeline/paths.yaml, relative to the folder it runs in, where `dvc repro`
writes them); else the one shipped in `pipeline/assets/`. A file is read once per process (`pipeline.models.cache`).

Two sets are shipped: the maze benchmark's (`pipeline/assets/`, 4 m lattice, 20 m sensor) and the
real-robot scale's (`pipeline/assets/real_robot/`, 1 m lattice, 10 m sensor; profiles/real_robot.yaml
trains them). `pick_model(kind, protocol)` takes, among the pipeline's model and the shipped ones
in that order, the first trained at the protocol's model inputs (`MODEL_INPUT_FIELDS`); when none
is, the first there (the planner then warns that it runs at other protocol values).
"""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.common.paths import MODELS, POLICIES
from pipeline.models.cache import load_once
from pipeline.models.exports import require_file
from pipeline.models.modeling_block_model import BlockModel, block_model_protocol, load_block_model
from pipeline.models.modeling_diffusion import load_policy
from pipeline.models.modeling_drl import DRLPolicy, load_drl_policy
from pipeline.models.modeling_inpainter import TracedInpainter, inpainter_from_payload, read_inpainter_export
from pipeline.prediction.node_predictor import InpaintFn
from pipeline.world.protocol import Protocol, model_input_differences

ASSETS = Path(__file__).resolve().parents[1] / "assets"
REAL_ROBOT_ASSETS = ASSETS / "real_robot"  # the models shipped for the real-robot scale (0.2 m / 1 m / 10 m)

PIPELINE_INPAINTER = MODELS.inpainter / "inpainter.pt"
SHIPPED_INPAINTER = ASSETS / "inpainter.pt"
PIPELINE_POLICY = {variant: paths.model / "policy.pt" for variant, paths in POLICIES.items()}
SHIPPED_POLICY = {"guide": ASSETS / "planner_guide.pt", "dare": ASSETS / "planner_dare.pt"}
PIPELINE_BLOCK_MODEL = MODELS.block_model / "block_model.pt"
SHIPPED_BLOCK_MODEL = ASSETS / "block_model.pt"
PIPELINE_DRL = MODELS.drl / "policy.pt"
SHIPPED_DRL = ASSETS / "planner_drl.pt"
PIPELINE_GATE = MODELS.sliver_gate / "sliver_gate.json"
SHIPPED_GATE = ASSETS / "sliver_gate.json"

# kind -> (the pipeline's file, the shipped files: maze scale first, then real-robot scale)
MODEL_FILES: dict[str, tuple[Path, tuple[Path, ...]]] = {
    "inpainter": (PIPELINE_INPAINTER, (SHIPPED_INPAINTER, REAL_ROBOT_ASSETS / "inpainter.pt")),
    "policy_guide": (PIPELINE_POLICY["guide"], (SHIPPED_POLICY["guide"], REAL_ROBOT_ASSETS / "planner_guide.pt")),
    "policy_dare": (PIPELINE_POLICY["dare"], (SHIPPED_POLICY["dare"], REAL_ROBOT_ASSETS / "planner_dare.pt")),
    "block_model": (PIPELINE_BLOCK_MODEL, (SHIPPED_BLOCK_MODEL, REAL_ROBOT_ASSETS / "block_model.pt")),
    "drl": (PIPELINE_DRL, (SHIPPED_DRL, REAL_ROBOT_ASSETS / "planner_drl.pt")),
    "gate": (PIPELINE_GATE, (SHIPPED_GATE, REAL_ROBOT_ASSETS / "sliver_gate.json")),
}


def model_protocol(kind: str, path: str | Path) -> dict | None:
    """The protocol the `kind` model at `path` was trained at, as its file records it (None: not
    recorded, which stands for the maze defaults the first shipped models were trained at)."""
    if kind == "inpainter":
        return inpainter_protocol(path)
    if kind.startswith("policy_"):
        return cached_policy(path)[1].get("protocol")
    if kind == "drl":
        return cached_drl_policy(path)[1].get("protocol")
    if kind == "gate":
        return load_once("gate_protocol", path, _gate_protocol)
    if kind == "block_model":
        return load_once("block_model_protocol", path, block_model_protocol)
    raise ValueError(f"unknown model kind {kind!r}; known: {', '.join(MODEL_FILES)}")


def _gate_protocol(path: Path) -> dict | None:
    """The protocol a sliver gate file records (its JSON's `protocol`); the gate itself is read by the planners."""
    try:
        return json.loads(path.read_text()).get("protocol")
    except (OSError, json.JSONDecodeError, AttributeError) as error:
        raise ValueError(f"{path}: not a sliver gate file ({error})") from None


def pick_model(kind: str, protocol: Protocol | None = None) -> Path | None:
    """The default `kind` model: of the pipeline's and the shipped files that exist, in that order,
    the first trained at `protocol`'s model inputs, else the first (None when there is none)."""
    pipeline, shipped = MODEL_FILES[kind]
    present = [path for path in (pipeline, *shipped) if path.is_file()]
    if protocol is not None:
        for path in present:
            if not model_input_differences(model_protocol(kind, path), protocol):
                return path
    return present[0] if present else None


# ----------------------------------------------------------------------------- inpainter
def _read_inpainter(path: Path) -> tuple[InpaintFn, dict | None]:
    payload = read_inpainter_export(path)
    model, _ = inpainter_from_payload(payload, path)
    return TracedInpainter(model).predict, payload.get("protocol")


def _load_inpainter_once(path: str | Path) -> tuple[InpaintFn, dict | None]:
    return load_once("inpainter", path, _read_inpainter)


def cached_inpainter(path: str | Path) -> InpaintFn:
    """The trained inpainter at `path` as a node image -> probability function, loaded once per process."""
    return _load_inpainter_once(path)[0]


def inpainter_protocol(path: str | Path) -> dict | None:
    """The protocol the inpainter at `path` was trained at, as recorded in its export (None: not recorded)."""
    return _load_inpainter_once(path)[1]


def inpainter_path(checkpoint: str | Path | None = None) -> Path:
    """`checkpoint`, else the pipeline's trained inpainter, else the shipped default; FileNotFoundError if none is there."""
    path = Path(checkpoint) if checkpoint else (pick_model("inpainter") or PIPELINE_INPAINTER)
    if not path.is_file():
        if checkpoint:
            raise FileNotFoundError(f"inpainter checkpoint {path} not found")
        raise FileNotFoundError(
            f"no inpainter checkpoint given, {PIPELINE_INPAINTER} does not exist and no default is shipped "
            f"({SHIPPED_INPAINTER}): train one with `dvc repro train_inpainter` or pass --checkpoint PATH"
        )
    return path


def resolve_inpainter(inpaint: InpaintFn | None, checkpoint: str | None) -> tuple[InpaintFn | None, str, Path | None]:
    """(inpaint function or None, a few words saying which predictor is used, its file or None)."""
    if inpaint is not None:
        return inpaint, "injected inpainter", None
    if checkpoint is not None:
        found = require_file(checkpoint, "an inpainter export")
        return cached_inpainter(found), f"trained inpainter {checkpoint}", found
    path = pick_model("inpainter")
    if path == PIPELINE_INPAINTER:
        return cached_inpainter(path), f"trained inpainter {path}", path
    if path is not None:
        return cached_inpainter(path), "shipped default inpainter", path
    return None, "no inpainter found: nothing predicted (frontier-only fallback)", None


# ----------------------------------------------------------------------------- diffusion policy
def _read_policy(path: Path) -> tuple[object, dict]:
    policy, meta = load_policy(path)
    return policy.trace_denoiser(), dict(meta.get("observations") or {})


def cached_policy(path: str | Path) -> tuple[object, dict]:
    """(the exported policy at `path`, the metadata of the observations it was trained on: variant,
    threshold, count_threshold, ...; {} for an export without it), loaded once per process (eval
    mode, traced denoiser)."""
    return load_once("policy", path, _read_policy)


def resolve_policy_path(kind: str, checkpoint: str | Path | None) -> Path:
    """`checkpoint`, else the pipeline's `kind` ("guide" or "dare") policy, else the shipped one."""
    if checkpoint is not None:
        return require_file(checkpoint, "a planner checkpoint")
    path = pick_model(f"policy_{kind}")
    if path is not None:
        return path
    raise FileNotFoundError(
        f"no trained {kind} policy: neither {PIPELINE_POLICY[kind]} nor the shipped {SHIPPED_POLICY[kind]} exists; "
        f"run `dvc repro train_planner` or pass policy_file=PATH"
    )


# ----------------------------------------------------------------------------- block model
def pipeline_or_shipped(checkpoint: str | Path | None, kind: str, what: str, stage: str) -> Path:
    """`checkpoint` (a `what` file), else the pipeline's `kind` model, else the shipped one;
    FileNotFoundError naming the `stage` that makes it when none is there."""
    if checkpoint is not None:
        return require_file(checkpoint, what)
    path = pick_model(kind)
    if path is not None:
        return path
    pipeline, (shipped, *_) = MODEL_FILES[kind]
    raise FileNotFoundError(
        f"no {what.removeprefix('a ')}: neither {pipeline} (`dvc repro {stage}`) nor the shipped "
        f"{shipped} exists; pass its option, e.g. policy_file=PATH"
    )


def resolve_block_model(checkpoint: str | None) -> Path:
    """`checkpoint`, else the pipeline's model in models/, else the shipped one."""
    return pipeline_or_shipped(checkpoint, "block_model", "a block model file", "train_block_model")


def block_model_for(checkpoint: str | None, model: BlockModel | None = None) -> tuple[BlockModel, str]:
    """(the block model, where it came from): `model` when injected, else loaded once per path."""
    if model is not None:
        return model, "injected block model"
    try:
        path = resolve_block_model(checkpoint)
    except FileNotFoundError as error:  # an option error, reported in one line like the others
        raise ValueError(str(error)) from None
    return load_once(
        "block_model", path, load_block_model
    ), f"block model {path if path != SHIPPED_BLOCK_MODEL else '(shipped)'}"


# ----------------------------------------------------------------------------- drl policy
def resolve_drl_path(checkpoint: str | Path | None) -> Path:
    """`checkpoint`, else the pipeline's drl policy in models/, else the shipped one."""
    return pipeline_or_shipped(checkpoint, "drl", "a drl policy export", "train_drl")


def cached_drl_policy(path: str | Path) -> tuple[DRLPolicy, dict]:
    """(the drl policy at `path`, what it was trained on), loaded once per process."""
    return load_once("drl", path, load_drl_policy)


# ----------------------------------------------------------------------------- sliver gate
def resolve_gate_path(gate_file: str | Path | None) -> Path:
    """`gate_file`, else the pipeline's fitted gate in models/ when present, else the shipped one."""
    if gate_file is not None:
        path = Path(gate_file)
        if not path.is_file():
            raise ValueError(f"sliver gate file {path} does not exist")
        return path
    return pick_model("gate") or SHIPPED_GATE
