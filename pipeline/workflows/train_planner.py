"""Stage II training and its report (the `train_planner` stage): the diffusion policy of one
variant trained on its observations, then its metrics and training curves."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pipeline.common.atomic import atomic_write_json
from pipeline.common.config import Section, every_key, maybe, text, whole
from pipeline.common.fingerprints import files_digest, settings_digest
from pipeline.common.paths import CHECKPOINTS, POLICIES
from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.models.modeling_diffusion import load_policy
from pipeline.reporting.training_figures import planner_training_curves
from pipeline.training.policy import PlannerTrainConfig, train_planner
from pipeline.training.run_setup import DEVICES, resume_point, start_afresh

CHECKPOINTS_OF = {variant: getattr(CHECKPOINTS, f"planner_{variant}") for variant in POLICIES}


class Settings(Section):
    """The `train_planner` section of params.yaml."""

    model: DiffusionPolicyConfig
    train: Annotated[
        PlannerTrainConfig, every_key(PlannerTrainConfig, optional=("val_accuracy_samples",))
    ]  # its default unless set
    accelerator: Annotated[str, text(note="Lightning's accelerator: cpu, gpu, auto")]
    devices: Annotated[int | list[int] | str, DEVICES]
    num_nodes: Annotated[int, whole(1, note="nodes of a multi-node DDP run")]
    threads: Annotated[int | None, maybe(whole(0, note="0: torch's default"), "torch's default")]
    experiment: Annotated[str, text(note="an MLflow experiment")]


def training_fingerprint(
    model: dict, train: dict, accelerator: str, devices: int | list[int] | str, observations: Path, num_nodes: int = 1
) -> str:
    """What a policy's weights depend on: its model and training settings, the device layout
    (devices x nodes: the global batch) and the observations' bytes (not the MLflow experiment or
    the thread count)."""
    layout = {"accelerator": accelerator, "devices": devices, **({"num_nodes": num_nodes} if num_nodes != 1 else {})}
    return settings_digest({"model": model, "train": train, **layout, "observations": files_digest([observations])})


def train_and_report(
    settings: Settings,
    variant: str,
    accelerator: str | None = None,
    devices: int | list[int] | str | None = None,
    afresh: bool = False,
    max_epochs: int | None = None,
) -> dict:
    """Train the `variant` policy from the `train_planner` settings and write its metrics and curves;
    the metrics ({} in a process of a multi-device run other than the first).

    A run killed part-way continues from its last epoch's checkpoint in checkpoints/planner_<variant>
    when the settings and observations are the same (`afresh` starts over regardless)."""
    paths = POLICIES[variant]
    # As the file names them: the fingerprint and the export record them.
    model, train = (dict(settings.as_written()[key] or {}) for key in ("model", "train"))
    if max_epochs is not None:  # checked as the file's values are, as a one-line error
        train["max_epochs"] = max_epochs
        PlannerTrainConfig.from_dict(train, "train_planner.train")
    accelerator = accelerator or settings.accelerator
    devices = devices or settings.devices
    checkpoint_dir = CHECKPOINTS_OF[variant]
    if not Path(paths.observations).is_file():  # before any checkpoint is decided on
        raise FileNotFoundError(f"{paths.observations}: no observations; run the build_observations stage first")
    fingerprint = training_fingerprint(model, train, accelerator, devices, paths.observations, settings.num_nodes)
    resume_from = None if afresh else resume_point(checkpoint_dir, fingerprint, f"train_planner {variant}")
    if resume_from is None:
        start_afresh(checkpoint_dir, fingerprint)
    export = train_planner(
        paths.observations,
        paths.model,
        model,
        train,
        accelerator=accelerator,
        devices=devices,
        num_nodes=settings.num_nodes,
        resume=resume_from is not None,
        checkpoint_dir=checkpoint_dir,
        experiment_name=settings.experiment,
        run_name=variant,
        num_threads=settings.threads,
    )
    if export is None:  # another process of a multi-device run: rank zero exports and reports
        return {}
    policy, meta = load_policy(export)
    history = meta.get("history", [])
    last = history[-1] if history else {}
    metrics = {
        "variant": variant,
        "num_parameters": policy.num_parameters(),
        "epochs": meta.get("epochs"),
        "train_seconds": meta.get("train_seconds"),
        "samples": meta.get("samples"),
        "val_loss": last.get("val_loss"),
        "val_first_step_accuracy": last.get("val_first_step_accuracy"),
        "trained_on": meta.get("trained_on"),  # torch build, CPU kernels, threads: weights differ across hosts
        "resumed_after_epochs": resume_from[1] if resume_from else None,  # None: trained in one go
    }
    atomic_write_json(paths.metrics, metrics)
    if history:
        planner_training_curves(history, paths.curves, f"{variant} diffusion planner")
    return metrics
