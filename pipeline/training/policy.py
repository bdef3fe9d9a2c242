"""Stage II training of the diffusion planner in Lightning.

DDPM loss (the model config's prediction type: clean actions by default, epsilon as DARE;
squared-cosine schedule from `diffusers`) on expert action chunks given T_o graph observations; AdamW with linear warm-up and cosine decay (the
`diffusers` schedule helper); EMA weights (`torch.optim.swa_utils`), which are what gets
exported and what validation measures. Validation holds out whole episodes and reports the
loss and how often the first sampled step equals the expert's.
"""

from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Any, Optional, cast

import lightning as L
import numpy as np
import torch
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn

from pipeline.common.config import config_dataclass, flag, fraction, maybe, positive, real, validate, whole
from pipeline.data.observations import PlannerDataset, crop_observations, load_observations
from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.models.modeling_diffusion import DiffusionPolicy, export_policy, load_policy
from pipeline.training.lightning_run import RunOptions, export, fit, start
from pipeline.training.run_setup import random_states, restore_random_states, torch_threads

EXPORT_NAME = "policy.pt"


@config_dataclass
class PlannerTrainConfig:
    """Training hyperparameters (the `train` mapping of params.yaml's `train_planner` section)."""

    max_epochs: Annotated[int, whole(1)] = 30  # >= 1: 0 epochs would export an untrained model over a trained one
    batch_size: Annotated[int, whole(1)] = 64
    lr: Annotated[float, positive()] = (
        3e-4  # AdamW (DARE: 1e-4 at 256 wide; the small default model takes a larger step)
    )
    weight_decay: Annotated[float, real(0.0)] = 1e-4
    warmup_steps: Annotated[int, whole(0)] = 100
    ema_decay: Annotated[float, fraction()] = 0.995
    val_fraction: Annotated[float, real(0.0, 1.0, high_open=True)] = 0.15  # share of episodes held out
    augment: Annotated[bool, flag()] = True  # random dihedral transforms of positions and actions
    seed: Annotated[int, whole(0)] = 0
    val_accuracy_samples: Annotated[int, whole(0)] = (
        64  # validation samples whose first step is sampled (K from the model config)
    )
    # Wall-clock cap on training (a timed GPU lease); the LR schedule still follows max_epochs.
    max_minutes: Annotated[float | None, maybe(positive("minutes"), "no cap")] = None

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None, root: str = "train") -> "PlannerTrainConfig":
        """Build from a dict (params.yaml's `train_planner.train`, a checkpoint's hyperparameters);
        a refused value or an unknown key is a one-line ValueError naming it as `root.key`."""
        return validate(cls, values, root)


def split_episodes(episode: np.ndarray, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(train rows, val rows), holding out whole episodes (at least one when there are two or more)."""
    ids = np.unique(episode)
    rng = np.random.default_rng(seed)
    n_val = int(round(val_fraction * len(ids)))
    if len(ids) >= 2:
        n_val = min(max(n_val, 1), len(ids) - 1)
    else:
        n_val = 0
    val_ids = rng.permutation(ids)[:n_val]
    is_val = np.isin(episode, val_ids)
    return np.nonzero(~is_val)[0], np.nonzero(is_val)[0]


def collate(samples: list[dict]) -> dict[str, torch.Tensor]:
    return {k: torch.stack([s[k] for s in samples]) for k in samples[0]}


class PlannerLightning(L.LightningModule):
    """The diffusion policy, its EMA copy, and the DDPM objective."""

    def __init__(self, model_config: dict[str, Any], train_config: dict[str, Any]) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.model_config = DiffusionPolicyConfig.from_dict(model_config)
        self.train_config = PlannerTrainConfig.from_dict(train_config)
        self.policy = DiffusionPolicy(self.model_config)
        self.ema = AveragedModel(
            self.policy, multi_avg_fn=get_ema_multi_avg_fn(self.train_config.ema_decay), use_buffers=True
        )
        self.ema.requires_grad_(
            False
        )  # updated by averaging, never by gradients (DDP refuses trainable unused weights)
        self.history: list[dict[str, float]] = []
        self.generators: list[torch.Generator | np.random.Generator] = []  # saved in checkpoints (`random_states`)
        self._epoch_losses: list[float] = []
        self._val: dict[str, list[float]] = {}
        self._epoch_start = time.perf_counter()

    def training_step(self, batch, batch_idx):
        loss = self.policy.compute_loss(batch)
        self.log("train_loss", loss, prog_bar=True, batch_size=len(batch["actions"]))
        self._epoch_losses.append(float(loss.detach()))
        return loss

    def on_train_batch_end(self, outputs, batch, batch_idx) -> None:
        self.ema.update_parameters(self.policy)

    def on_train_epoch_start(self) -> None:
        self._epoch_losses = []
        self._epoch_start = time.perf_counter()

    def on_validation_epoch_start(self) -> None:
        self._val = {"loss": [], "first_step_hits": [], "first_step_count": []}

    def validation_step(self, batch, batch_idx):
        ema_policy: DiffusionPolicy = self.ema.module  # type: ignore[assignment]
        generator = torch.Generator(device=batch["actions"].device).manual_seed(batch_idx)
        with torch.random.fork_rng(devices=[]):  # the same noise every epoch: a comparable validation loss
            torch.manual_seed(batch_idx)
            loss = ema_policy.compute_loss(batch)
        self._val["loss"].append(float(loss))
        seen = int(sum(self._val["first_step_count"]))
        budget = self.train_config.val_accuracy_samples - seen
        if budget > 0:
            obs = {k: v[:budget] for k, v in batch.items() if k != "actions"}
            deltas = ema_policy.predict_action(obs, generator=generator)["deltas"]
            hits = (deltas[:, 0] == batch["actions"][:budget, 0]).all(dim=-1)
            self._val["first_step_hits"].append(float(hits.sum()))
            self._val["first_step_count"].append(float(len(hits)))

    def on_validation_epoch_end(self) -> None:
        if self.trainer.sanity_checking or not self._val["loss"]:
            return
        # Sums over this process's batches, added up across processes: every rank of a
        # multi-device run logs (and ModelCheckpoint ranks by) the loss over all held-out steps.
        sums = torch.tensor(
            [
                sum(self._val["loss"]),
                len(self._val["loss"]),
                sum(self._val["first_step_hits"]),
                sum(self._val["first_step_count"]),
            ],
            dtype=torch.float64,
            device=self.device,
        )
        if self.trainer.world_size > 1:
            sums = self.trainer.strategy.reduce(sums, reduce_op="sum")
        loss_sum, batches, hits, count = (float(v) for v in sums.cpu())
        val_loss = loss_sum / batches
        accuracy = hits / count if count else float("nan")
        self.log("val_loss", val_loss)
        self.log("val_first_step_accuracy", accuracy)
        self.history.append(
            {
                "epoch": int(self.current_epoch),
                "train_loss": float(np.mean(self._epoch_losses)) if self._epoch_losses else float("nan"),
                "val_loss": val_loss,
                "val_first_step_accuracy": accuracy,
                "seconds": time.perf_counter() - self._epoch_start,
            }
        )

    def configure_optimizers(self):
        from diffusers.optimization import get_cosine_schedule_with_warmup

        tc = self.train_config
        optimizer = torch.optim.AdamW(self.policy.parameters(), lr=tc.lr, weight_decay=tc.weight_decay)
        total = max(int(self.trainer.estimated_stepping_batches), tc.warmup_steps + 1)
        schedule = get_cosine_schedule_with_warmup(
            optimizer, num_warmup_steps=min(tc.warmup_steps, total // 4), num_training_steps=total
        )
        return {"optimizer": optimizer, "lr_scheduler": {"scheduler": schedule, "interval": "step"}}

    def on_save_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        checkpoint["history"] = self.history
        checkpoint["random_states"] = random_states(self.generators)

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        self.history = list(checkpoint.get("history", []))
        restore_random_states(checkpoint.get("random_states"), self.generators)


def start_from(module: PlannerLightning, export: str | Path) -> None:
    """Load a policy export's weights into the module's policy and its EMA copy (same model config)."""
    policy, _ = load_policy(export)
    if policy.config.to_dict() != module.model_config.to_dict():
        raise ValueError(
            f"{export}: its model config differs from the one being trained; start from an export of "
            "the same config or from scratch"
        )
    module.policy.load_state_dict(policy.state_dict())
    module.ema.module.load_state_dict(policy.state_dict())


def train_planner(
    observations: str | Path,
    out_dir: str | Path,
    model_config: DiffusionPolicyConfig | dict[str, Any] | None = None,
    train_config: PlannerTrainConfig | dict[str, Any] | None = None,
    *,
    accelerator: str = "cpu",
    devices: int | list[int] | str = 1,
    num_nodes: int = 1,
    resume: bool = False,
    tracking_uri: Optional[str] = None,
    mlflow: bool = True,
    experiment_name: str = "planner",
    run_name: Optional[str] = None,
    progress: bool = False,
    num_threads: Optional[int] = None,
    checkpoint_dir: str | Path | None = None,
    init_policy: str | Path | None = None,
) -> Path | None:
    """Train on an observation file (build_observations stage); returns the exported policy.pt
    (None in the other processes of a multi-device run: only rank zero exports).

    Lightning's checkpoints (`last.ckpt`, `best.ckpt`, each written atomically) go to
    `checkpoint_dir` (default: `out_dir`). `resume=True` continues from its last.ckpt
    (optimiser, EMA and history included) when it exists; otherwise the old checkpoints are
    set aside while it trains (`fresh_checkpoints`), once the settings and the data have been
    checked (a run that fails early leaves them alone). `init_policy`, a policy export of the
    same model config, gives a fresh run its starting weights (its EMA copy too) instead of a
    random draw; a resumed run continues from its checkpoint.
    """
    tc = (
        train_config
        if isinstance(train_config, PlannerTrainConfig)
        else PlannerTrainConfig.from_dict(train_config or {})
    )
    mc = (
        model_config
        if isinstance(model_config, DiffusionPolicyConfig)
        else DiffusionPolicyConfig.from_dict(model_config or {})
    )
    run = RunOptions.from_dict(
        dict(
            out_dir=out_dir,
            checkpoint_dir=checkpoint_dir,
            accelerator=accelerator,
            devices=devices,
            num_nodes=num_nodes,
            resume=resume,
            mlflow=mlflow,
            tracking_uri=tracking_uri,
            experiment=experiment_name,
            run_name=run_name,
            progress=progress,
        )
    )
    arrays, meta = load_observations(observations)
    n_max = arrays["features"].shape[1]
    if n_max < mc.max_nodes or arrays["neighbors"].shape[2] != mc.max_neighbors:
        raise ValueError(
            f"{observations}: observations have {n_max} nodes x {arrays['neighbors'].shape[2]} neighbours but the model "
            f"expects {mc.max_nodes} x {mc.max_neighbors}; rebuild the observations or change the model config"
        )
    arrays = crop_observations(arrays, mc.max_nodes)  # larger stored graphs train a smaller model
    if arrays["actions"].shape[1] < mc.horizon:
        raise ValueError(
            f"{observations}: actions hold {arrays['actions'].shape[1]} steps, the model's horizon is {mc.horizon}"
        )
    arrays["actions"] = arrays["actions"][:, : mc.horizon]
    with torch_threads(num_threads):
        start(run, tc.seed)
        train_rows, val_rows = split_episodes(arrays["episode"], tc.val_fraction, tc.seed)
        train_set = PlannerDataset(arrays, mc.obs_steps, train_rows, augment=tc.augment, seed=tc.seed)
        # Validation samples first steps from its first `val_accuracy_samples` rows: shuffled once (fixed seed),
        # they spread over every held-out episode instead of the first steps of one.
        val_rows = np.random.default_rng(tc.seed).permutation(val_rows) if len(val_rows) else train_rows[:1]
        val_set = PlannerDataset(arrays, mc.obs_steps, val_rows)
        generator = torch.Generator().manual_seed(tc.seed)
        # PlannerDataset is a map-style dataset (__len__, __getitem__) without torch's base class.
        train_loader: torch.utils.data.DataLoader[Any] = torch.utils.data.DataLoader(
            cast("torch.utils.data.Dataset[Any]", train_set),
            batch_size=tc.batch_size,
            shuffle=True,
            collate_fn=collate,
            generator=generator,
            drop_last=len(train_set) > tc.batch_size,
        )
        val_loader: torch.utils.data.DataLoader[Any] = torch.utils.data.DataLoader(
            cast("torch.utils.data.Dataset[Any]", val_set), batch_size=tc.batch_size, shuffle=False, collate_fn=collate
        )
        module = PlannerLightning(mc.to_dict(), asdict(tc))
        if init_policy is not None and run.resume_from() is None:
            start_from(module, init_policy)
        module.generators = [generator, train_set.rng]  # the shuffle and the augmentation resume where they were
        hyperparams = {
            **{f"model.{k}": v for k, v in mc.to_dict().items()},
            **{f"train.{k}": v for k, v in asdict(tc).items()},
            "observations": str(observations),
            "samples": len(arrays["episode"]),
        }
        result = fit(
            run,
            module,
            monitor="val_loss",
            mode="min",
            max_epochs=tc.max_epochs,
            max_minutes=tc.max_minutes,
            fit_args={"train_dataloaders": train_loader, "val_dataloaders": val_loader},
            hyperparams=hyperparams,
            trainer_options={"log_every_n_steps": 5, "gradient_clip_val": 1.0},
            data=Path(observations),
        )
        export_path = run.out_dir / EXPORT_NAME

        def write(host: dict[str, Any]) -> None:
            export_policy(
                cast(DiffusionPolicy, module.ema.module).cpu().eval(),
                export_path,
                train_config=asdict(tc),
                history=list(module.history),
                train_seconds=round(result.seconds, 2),
                epochs=int(result.trainer.current_epoch),
                samples={"train": len(train_rows), "val": len(val_rows)},
                trained_on=host,
                observations=meta,
            )

        return export(result, export_path, write, module.policy.num_parameters())
