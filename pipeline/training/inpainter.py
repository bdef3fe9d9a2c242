"""Stage I training: the FFC inpainter on (observed, ground-truth) node-image pairs.

Data: the shards of a Stage I data set (read through its manifest), grouped by image size
(32, 40, 48); a batch holds one size. Validation holds out whole mazes (a maze is
recognised by its ground-truth image), about `val_fraction` of the pairs: with few
training mazes a network learns to recognise a maze from its explored part and recall the
rest, which a split that shares mazes would count as inference. (`split="rollout"` keeps
the last pairs of each shard and size instead: separate rollouts, same mazes.)

Augmentation: the 8 flips / quarter turns of the square (the lattice has no preferred
direction); optionally (`hide_prob`) the observations inside a random box are turned back
to unknown, an earlier view of the same exploration (off by default: it did not help on
the default data).

Loss: binary cross-entropy on the hole pixels (unknown and inside the lattice) plus
`known_weight` times the BCE on the known pixels (LaMa's L1 on known pixels, as BCE for a
probability output); padding never counts. With `adversarial_weight > 0` a small
conditional PatchGAN discriminator is trained alongside (non-saturating loss with an R1
penalty, as LaMa's `r1` adversarial loss); off by default.

Validation: precision, recall and F1 of the predicted free nodes (probability >= tau) over
the hole pixels, summed over the validation set. Checkpoints (`last.ckpt`, `best.ckpt` by
validation F1) go to the checkpoint folder; `resume=True` continues from `last.ckpt`. At the
end the best weights are exported as a small `inpainter.pt` (config + state_dict +
metrics) that `load_inpainter` reads for inference.
"""

from __future__ import annotations

import math
import pickle
import time
import warnings
import zipfile
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Any, Optional, cast

import lightning as L
import torch
import torch.nn.functional as F

from pipeline.common.config import config_dataclass, flag, fraction, maybe, positive, real, text, validate, whole
from pipeline.models.big_lama import load_big_lama_generator
from pipeline.models.configuration_inpainter import InpainterConfig
from pipeline.models.exports import export_kind
from pipeline.models.modeling_inpainter import PIXEL_FREE_MIN, InpainterModel, export_inpainter, is_inpainter_export
from pipeline.training.inpainter_data import SPLITS, InpainterDataModule, maze_count, pair_count
from pipeline.training.inpainter_losses import (
    PatchDiscriminator,
    hole_and_known,
    hole_counts,
    inpainting_loss,
    precision_recall_f1,
)
from pipeline.training.lightning_run import RunOptions, export, fit, start
from pipeline.training.run_setup import one_line, random_states, restore_random_states, torch_threads

EXPORT_NAME = "inpainter.pt"


@config_dataclass
class TrainConfig:
    """Training hyperparameters (the `train_inpainter` section of params.yaml, minus the model and
    the run's settings)."""

    max_epochs: Annotated[int, whole(1)] = 40  # >= 1: 0 epochs would export an untrained model over a trained one
    batch_size: Annotated[int, whole(1)] = 16
    lr: Annotated[float, positive()] = 1e-3  # Adam (LaMa's generator learning rate)
    weight_decay: Annotated[float, real(0.0)] = 0.0
    lr_min_factor: Annotated[float, fraction()] = 0.05  # cosine decay to lr * this at the last epoch
    known_weight: Annotated[float, real(0.0)] = 0.1  # weight of the BCE on known pixels, relative to the hole BCE
    hole_pos_weight: Annotated[float, real(0.0)] = (
        1.0  # BCE weight of free hole pixels (>1 favours recall, <1 precision)
    )
    adversarial_weight: Annotated[float, real(0.0)] = 0.0  # > 0 trains a PatchGAN discriminator alongside
    discriminator_lr: Annotated[float, positive()] = 1e-4
    discriminator_width: Annotated[int, whole(1)] = 32
    r1_weight: Annotated[float, real(0.0)] = 0.001  # R1 gradient penalty on real images (LaMa's gp_coef)
    threshold: Annotated[float, fraction("P(free)")] = (
        0.5  # tau: probability at or above which a node is predicted free
    )
    val_fraction: Annotated[float, real(0.0, 1.0, low_open=True, high_open=True)] = 0.2
    split: Annotated[str, text(SPLITS)] = (
        "maze"  # hold out whole mazes ("maze") or the last pairs of each rollout group ("rollout")
    )
    augment: Annotated[bool, flag()] = True  # random flips and 90-degree rotations (the lattice is symmetric)
    hide_prob: Annotated[float, fraction()] = 0.0  # chance per training pair of hiding the observations in a random box
    seed: Annotated[int, whole(0)] = 0
    # Wall-clock cap on training (a timed GPU lease); the LR schedule still follows max_epochs.
    max_minutes: Annotated[float | None, maybe(positive("minutes"), "no cap")] = None

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None, root: str = "train_inpainter") -> "TrainConfig":
        """Build from a dict (params.yaml's `train_inpainter` section without the model and the
        run's settings); a refused value or an unknown key is a one-line ValueError naming it as `root.key`."""
        return validate(cls, values, root)


# ----------------------------------------------------------------------------- Lightning module
class InpainterLightning(L.LightningModule):
    """Generator (+ optional discriminator), manual optimisation, hole metrics and a history."""

    def __init__(self, model_config: dict[str, Any], train_config: dict[str, Any]) -> None:
        super().__init__()
        self.save_hyperparameters()
        self.model_config = InpainterConfig.from_dict(model_config)
        self.train_config = TrainConfig.from_dict(train_config)
        self.generator = InpainterModel(self.model_config)
        tc = self.train_config
        self.discriminator = (
            PatchDiscriminator(self.model_config.in_channels + 1, tc.discriminator_width)
            if tc.adversarial_weight > 0
            else None
        )
        self.automatic_optimization = False
        self.history: list[dict[str, float]] = []
        self._train_sums = torch.zeros(2, dtype=torch.float64)  # loss * n, n
        self._val_sums = torch.zeros(5, dtype=torch.float64)  # tp, fp, fn, loss * n, n
        self._epoch_started = time.perf_counter()

    # -- optimisation -----------------------------------------------------------------
    def configure_optimizers(self):
        tc = self.train_config
        gen_opt = torch.optim.Adam(self.generator.parameters(), lr=tc.lr, weight_decay=tc.weight_decay)

        def cosine(epoch: int) -> float:  # reads max_epochs at call time: a resumed, longer run decays over it
            total = max(1, (cast(int, self.trainer.max_epochs) if self._trainer is not None else tc.max_epochs) - 1)
            t = min(epoch, total) / total
            return tc.lr_min_factor + (1 - tc.lr_min_factor) * 0.5 * (1 + math.cos(math.pi * t))

        gen_sched = torch.optim.lr_scheduler.LambdaLR(gen_opt, cosine)
        if self.discriminator is None:
            return [gen_opt], [gen_sched]
        disc_opt = torch.optim.Adam(self.discriminator.parameters(), lr=tc.discriminator_lr, betas=(0.5, 0.999))
        return [gen_opt, disc_opt], [gen_sched]

    def _optimizers(self) -> list:
        opts = self.optimizers()
        return list(opts) if isinstance(opts, (list, tuple)) else [opts]

    def _disc_input(
        self, encoded: torch.Tensor, free_prob: torch.Tensor, observed: torch.Tensor, valid: torch.Tensor
    ) -> torch.Tensor:
        """The discriminator's view: input channels + image with known pixels as observed, padding 0."""
        hole, known = hole_and_known(observed, valid)
        known_value = (observed >= PIXEL_FREE_MIN).to(free_prob.dtype)
        image = torch.where(hole, free_prob, known_value) * 2 - 1
        image = torch.where(valid.bool(), image, torch.zeros_like(image))
        return torch.cat([encoded, image], dim=1)

    def training_step(self, batch, batch_idx):
        observed, target, valid = (t.unsqueeze(1) for t in batch)
        tc = self.train_config
        opts = self._optimizers()
        encoded = self.generator.encode(observed)
        logits = self.generator.forward_encoded_logits(encoded)
        loss, parts = inpainting_loss(logits, observed, target, valid, tc.known_weight, tc.hole_pos_weight)
        total = loss
        if self.discriminator is not None:
            gen_opt, disc_opt = opts
            real = self._disc_input(encoded, (target >= PIXEL_FREE_MIN).float(), observed, valid)
            fake = self._disc_input(encoded, torch.sigmoid(logits), observed, valid)
            # Discriminator step: non-saturating loss + R1 penalty on real images.
            real_d = real.detach().requires_grad_(tc.r1_weight > 0)
            d_real = self.discriminator(real_d)
            d_fake = self.discriminator(fake.detach())
            d_loss = F.softplus(-d_real).mean() + F.softplus(d_fake).mean()
            if tc.r1_weight > 0:
                (grad,) = torch.autograd.grad(d_real.sum(), real_d, create_graph=True)
                d_loss = d_loss + tc.r1_weight * grad.pow(2).flatten(1).sum(1).mean()
            disc_opt.zero_grad()
            self.manual_backward(d_loss)
            disc_opt.step()
            # Generator's adversarial term (the discriminator's grads from it are cleared next step).
            adv = F.softplus(-self.discriminator(fake)).mean()
            total = loss + tc.adversarial_weight * adv
            self.log_dict(
                {"train_adv": adv.detach(), "train_disc": d_loss.detach()},
                on_step=False,
                on_epoch=True,
                batch_size=observed.shape[0],
            )
        else:
            gen_opt = opts[0]
        gen_opt.zero_grad()
        self.manual_backward(total)
        gen_opt.step()
        n = observed.shape[0]
        self._train_sums += torch.tensor([float(loss.detach()) * n, n], dtype=torch.float64)
        self.log_dict(
            {"train_loss": loss.detach(), "train_hole_bce": parts["hole"], "train_known_bce": parts["known"]},
            on_step=False,
            on_epoch=True,
            prog_bar=True,
            batch_size=n,
        )
        return total.detach()

    def on_train_epoch_start(self) -> None:
        self._train_sums.zero_()
        self._epoch_started = time.perf_counter()

    def on_train_epoch_end(self) -> None:
        schedulers: Any = self.lr_schedulers()  # one scheduler, a list of them or None
        for scheduler in schedulers if isinstance(schedulers, list) else [schedulers]:
            if scheduler is not None:
                scheduler.step()

    # -- validation -----------------------------------------------------------------------
    def on_validation_epoch_start(self) -> None:
        self._val_sums.zero_()

    def validation_step(self, batch, batch_idx):
        observed, target, valid = (t.unsqueeze(1) for t in batch)
        tc = self.train_config
        logits = self.generator.forward_logits(observed)
        loss, _ = inpainting_loss(logits, observed, target, valid, tc.known_weight, tc.hole_pos_weight)
        counts = hole_counts(torch.sigmoid(logits), observed, target, valid, tc.threshold).cpu()
        n = observed.shape[0]
        self._val_sums += torch.cat([counts, torch.tensor([float(loss) * n, n], dtype=torch.float64)])

    def on_validation_epoch_end(self) -> None:
        sums = self._val_sums.to(self.device)
        if self.trainer.world_size > 1:
            sums = self.trainer.strategy.reduce(sums, reduce_op="sum")
        sums = sums.cpu()
        metrics = precision_recall_f1(sums[:3].tolist())
        val_loss = float(sums[3] / max(1.0, float(sums[4])))
        self.log_dict(
            {
                "val_loss": val_loss,
                "val_precision": metrics["precision"],
                "val_recall": metrics["recall"],
                "val_f1": metrics["f1"],
            },
            prog_bar=True,
            sync_dist=False,
        )
        if self.trainer.sanity_checking:
            return
        train = self._train_sums.to(self.device)
        if self.trainer.world_size > 1:
            train = self.trainer.strategy.reduce(train, reduce_op="sum")
        train = train.cpu()
        record = {
            "epoch": int(self.current_epoch),
            "train_loss": float(train[0] / max(1.0, float(train[1]))),
            "val_loss": val_loss,
            "val_precision": metrics["precision"],
            "val_recall": metrics["recall"],
            "val_f1": metrics["f1"],
            "lr": float(self._optimizers()[0].param_groups[0]["lr"]),
            "seconds": time.perf_counter() - self._epoch_started,
        }
        self.history = [h for h in self.history if h["epoch"] != record["epoch"]] + [record]

    # -- checkpoint extras ------------------------------------------------------------
    def on_save_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        checkpoint["inpainter_history"] = list(self.history)
        checkpoint["random_states"] = random_states()

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        self.history = list(checkpoint.get("inpainter_history", []))
        restore_random_states(checkpoint.get("random_states"))


# ----------------------------------------------------------------------------- export / load
# What torch.save wrote before its zip format: a pickled magic number (protocol 2) opens the file.
_LEGACY_TORCH_HEAD = pickle.dumps(0x1950A86A20F9469CFC6C, protocol=2)


def read_init_checkpoint(path: str | Path) -> dict[str, Any]:
    """The dict in an (official Big-LaMa) checkpoint named by the user, checked before use.

    FileNotFoundError if absent; ValueError if it is not a torch.save file or cannot be read.
    Tensors-only loading first; a valid archive that holds other pickled objects (LaMa's
    Lightning checkpoints keep config objects) is then unpickled fully, with a warning, since
    that runs code from the file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"init checkpoint {path} not found")
    with open(path, "rb") as handle:
        head = handle.read(len(_LEGACY_TORCH_HEAD))
    if not (zipfile.is_zipfile(path) or head == _LEGACY_TORCH_HEAD):
        raise ValueError(f"{path}: not a readable checkpoint (not a file written by torch.save)")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError:  # refused by weights_only: e.g. OmegaConf objects in LaMa's hyper_parameters
        warnings.warn(
            f"{path}: not loadable with weights_only=True; unpickling it fully (trust the file)", stacklevel=3
        )
        try:
            payload = torch.load(path, map_location="cpu", weights_only=False)
        except Exception as error:  # noqa: BLE001 - damaged, or its classes are not importable here
            raise ValueError(f"{path}: not a readable checkpoint ({one_line(error)})") from None
    except Exception as error:  # noqa: BLE001 - a damaged archive
        raise ValueError(f"{path}: not a readable checkpoint ({one_line(error)})") from None
    if not isinstance(payload, dict):
        raise ValueError(f"{path}: not a readable checkpoint (it holds a {type(payload).__name__}, not a dict)")
    if export_kind(payload) == "policy":  # else it would be taken for Big-LaMa weights and fail on their keys
        raise ValueError(f"{path}: a planner policy export, not an inpainter export or a Big-LaMa checkpoint")
    return payload


# ----------------------------------------------------------------------------- entry point
def is_big_lama_layout(config: InpainterConfig) -> bool:
    reference = InpainterConfig.big_lama(
        in_channels=config.in_channels, out_channels=config.out_channels, input_encoding=config.input_encoding
    )
    return config == reference


def train_inpainter(
    model_config: InpainterConfig | dict[str, Any] | None = None,
    data_dir: str | Path = "data/pairs",
    out_dir: str | Path = "models/inpainter",
    *,
    max_epochs: Optional[int] = None,
    batch_size: Optional[int] = None,
    lr: Optional[float] = None,
    accelerator: str = "cpu",
    devices: int | list[int] | str = 1,
    num_nodes: int = 1,
    resume: bool = False,
    tracking_uri: Optional[str] = None,
    init_checkpoint: Optional[str | Path] = None,
    train_config: TrainConfig | dict[str, Any] | None = None,
    mlflow: bool = True,
    experiment_name: str = "inpainter",
    run_name: Optional[str] = None,
    progress: bool = False,
    num_threads: Optional[int] = None,
    artifact_location: Optional[str] = None,
    protocol: Optional[dict[str, Any]] = None,
    checkpoint_dir: Optional[str | Path] = None,
) -> Path | None:
    """Train the inpainter on a Stage I data set; returns the path of the exported `inpainter.pt`
    (None in the other processes of a multi-device run: only rank zero exports).

    `max_epochs`, `batch_size` and `lr` override `train_config`. Lightning's checkpoints
    (`last.ckpt`, `best.ckpt`, each written atomically) go to `checkpoint_dir` (default:
    `out_dir`). `resume=True` continues from its `last.ckpt` (epoch counter, optimiser and
    history included) when it exists; otherwise the old checkpoints in `out_dir` are set aside while it trains
    (`fresh_checkpoints`), once the settings, the init checkpoint and the data have been
    checked (a run that fails early leaves them alone; bad settings raise a one-line ValueError). `init_checkpoint`
    is an official (Big-)LaMa checkpoint whose `generator.*` weights start the training
    (the model then takes the Big-LaMa layout), or one of our `inpainter.pt` exports (the
    shipped default, say), fine-tuned in its own layout. MLflow logs to `tracking_uri` (default:
    $MLFLOW_TRACKING_URI or sqlite:///mlflow.db). `num_threads` sets torch's CPU threads
    for the run (1 is often fastest for these small images on a busy machine). `protocol`
    (`Protocol.to_dict()` of the pairs) is recorded in the export, so planners can warn when run at another.
    `artifact_location` is where a newly created MLflow experiment keeps its artifacts
    (MLflow's default: ./mlruns).
    """
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
            artifact_location=artifact_location,
            progress=progress,
        )
    )
    tc = train_config if isinstance(train_config, TrainConfig) else TrainConfig.from_dict(train_config or {})
    overrides = {k: v for k, v in (("max_epochs", max_epochs), ("batch_size", batch_size), ("lr", lr)) if v is not None}
    tc = TrainConfig.from_dict({**asdict(tc), **overrides})
    if isinstance(model_config, dict):
        model_config = InpainterConfig.from_dict(model_config)
    with torch_threads(num_threads):
        return _train(model_config or InpainterConfig(), tc, Path(data_dir), run, init_checkpoint, protocol)


def _train(
    model_config: InpainterConfig,
    tc: TrainConfig,
    data_dir: Path,
    run: RunOptions,
    init_checkpoint: Optional[str | Path],
    protocol: Optional[dict[str, Any]],
) -> Path | None:
    # Everything that can fail is checked before a file is touched or an MLflow run is made: the
    # settings, the init checkpoint and the data; old checkpoints go only just before fit().
    init_weights = None
    if init_checkpoint is not None:
        # Read even when resuming: an export's layout must be known to rebuild the network for last.ckpt.
        init_weights = read_init_checkpoint(init_checkpoint)
        if is_inpainter_export(init_weights):  # our own export (the shipped default, an earlier run): fine-tune it
            exported = InpainterConfig.from_dict(init_weights["config"])
            if exported != model_config:
                warnings.warn(
                    f"init_checkpoint is an inpainter export: using its layout (ngf {exported.ngf}, "
                    f"{exported.n_blocks} blocks), not the configured one",
                    stacklevel=3,
                )
                model_config = exported
        elif not is_big_lama_layout(model_config):
            warnings.warn(
                "init_checkpoint holds Big-LaMa weights: using the Big-LaMa layout (InpainterConfig.big_lama())",
                stacklevel=3,
            )
            model_config = InpainterConfig.big_lama()
        if run.resume_from() is not None:  # a resumed run continues from last.ckpt, not from these weights
            init_weights = None
    data = InpainterDataModule(data_dir, tc.batch_size, tc.val_fraction, tc.augment, tc.seed, tc.hide_prob, tc.split)
    data.setup("fit")  # the data check (no random state involved): before the MLflow logger exists
    start(run, tc.seed)
    module = InpainterLightning(model_config.to_dict(), asdict(tc))
    if init_weights is not None and is_inpainter_export(init_weights):
        module.generator.load_state_dict(init_weights["state_dict"])
        print(
            f"initialised the generator from {init_checkpoint} (an inpainter export): "
            f"{len(init_weights['state_dict'])} tensors"
        )
        del init_weights
    elif init_weights is not None:
        try:
            summary = load_big_lama_generator(module.generator, init_weights)
        except (KeyError, RuntimeError, ValueError) as error:
            raise ValueError(f"{init_checkpoint}: {error}") from None
        del init_weights
        print(
            f"initialised the generator from {init_checkpoint}: {summary['loaded']} tensors, adapted {summary['adapted']}"
        )

    result = fit(
        run,
        module,
        monitor="val_f1",
        mode="max",
        max_epochs=tc.max_epochs,
        max_minutes=tc.max_minutes,
        fit_args={"datamodule": data},
        unused_parameters=tc.adversarial_weight > 0,
        trainer_options={"use_distributed_sampler": False, "log_every_n_steps": 1},
        data=data_dir,
    )
    export_path = run.out_dir / EXPORT_NAME

    def write(host: dict[str, Any]) -> None:
        if data.train_pairs is None or data.val_pairs is None:
            raise RuntimeError("fit() sets up the data module before the export")
        best_path = result.checkpoint.best_model_path
        generator = module.generator
        if best_path and Path(best_path).is_file():
            state = torch.load(best_path, map_location="cpu", weights_only=True)["state_dict"]
            generator = InpainterModel(module.model_config)
            generator.load_state_dict(
                {k[len("generator.") :]: v for k, v in state.items() if k.startswith("generator.")}
            )
        history = list(module.history)
        best = max(history, key=lambda h: h["val_f1"]) if history else {}
        export_inpainter(
            generator.cpu().eval(),
            export_path,
            threshold=tc.threshold,
            train_config=asdict(tc),
            history=history,
            best_epoch=int(best.get("epoch", -1)),
            val_metrics={k: float(v) for k, v in best.items() if k.startswith("val_")},
            train_seconds=round(result.seconds, 2),  # this fit() call (a resumed run counts its own part)
            epoch_seconds_total=round(sum(h["seconds"] for h in history), 2),  # all epochs, across resumes
            epochs=int(result.trainer.current_epoch),
            trained_on=host,
            pairs={"train": pair_count(data.train_pairs), "val": pair_count(data.val_pairs)},
            mazes={"train": maze_count(data.train_pairs), "val": maze_count(data.val_pairs)},
            **({"protocol": dict(protocol)} if protocol else {}),  # what the pairs were drawn at (planners check it)
        )

    return export(result, export_path, write, module.generator.num_parameters())
