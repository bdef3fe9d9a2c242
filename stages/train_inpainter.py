"""DVC stage: Stage I training of the node-image inpainter (LaMa's FFC generator, small default).

Reads the `train_inpainter` section of params.yaml (and the shared `protocol`, recorded in the
export so that planners can warn when run at another); trains on the Stage I pairs in
data/pairs/; writes models/inpainter/inpainter.pt (for inference; Lightning's last.ckpt and
best.ckpt go to checkpoints/inpainter/, where a killed run resumes from when its settings and
data are the same), reports/inpainter_metrics.json (validation precision / recall /
F1 of predicted free nodes in unknown space, per threshold; parameters; training time),
reports/inpainter_curves.png and reports/inpainter_samples.png. Validation holds out whole
mazes by default (`split: maze`), so its precision measures inference in unseen mazes.
"""

from __future__ import annotations

from typing import Any, Optional

from pipeline.common.params import load_params, params_section
from pipeline.common.paths import MODELS
from pipeline.common.settings import (AnyOf, Fields, Flag, ListOf, Maybe, Real, Text, Whole, check_stage, config_mapping,
                                      fraction, positive)
from pipeline.models.configuration_inpainter import INPUT_ENCODINGS, InpainterConfig
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.train_inpainter import train_and_report
from pipeline.world.protocol import Protocol

# Every key may be left out: the stage trains with TrainConfig's and InpainterConfig's defaults for those.
SETTINGS_KEYS = {
    "model": config_mapping(InpainterConfig, {
        "ngf": Whole(1), "n_downsampling": Whole(0), "n_blocks": Whole(0), "ratio_gin": fraction(), "ratio_gout": fraction(),
        "input_encoding": Text(tuple(INPUT_ENCODINGS)),
    }, extra={"big_lama": Flag()}),
    "max_epochs": Whole(1), "batch_size": Whole(1), "lr": positive(), "lr_min_factor": fraction(),
    "weight_decay": Real(0.0), "known_weight": Real(0.0), "hole_pos_weight": Real(0.0), "adversarial_weight": Real(0.0),
    "discriminator_lr": positive(), "discriminator_width": Whole(1), "r1_weight": Real(0.0),
    "threshold": fraction("P(free)"), "val_fraction": Real(0.0, 1.0, low_open=True, high_open=True),
    "split": Text(("maze", "rollout")), "augment": Flag(), "hide_prob": fraction(), "seed": Whole(0),
    "max_minutes": Maybe(positive("minutes"), "no cap"),
    "accelerator": Maybe(Text(note="Lightning's accelerator: cpu, gpu, auto"), "cpu"),
    "devices": Maybe(AnyOf((Whole(1), Whole(-1, -1), ListOf(Whole(0)), Text(("auto",))),
                           "a number of devices >= 1, -1 (all), a list of device indices or 'auto'"), "1"),
    "threads": Maybe(Whole(0, note="0: torch's default"), "torch's default"),
    "init_checkpoint": Maybe(Text(note="a Big-LaMa checkpoint or an inpainter export"), "random weights"),
    "experiment": Maybe(Text(note="an MLflow experiment"), "inpainter"),
}
SETTINGS = Fields(SETTINGS_KEYS, frozenset(SETTINGS_KEYS))


def main(
    params_path: str = "params.yaml",
    accelerator: Optional[str] = None,
    devices: Optional[int | str] = None,
    afresh: bool = False,
    init_checkpoint: Optional[str] = None,
    tracking_uri: Optional[str] = None,
    progress: bool = False,
    artifact_location: Optional[str] = None,
) -> dict[str, Any]:
    check_stage(params_path, "train_inpainter", SETTINGS)
    params = load_params(params_path)
    section = params_section(params, "train_inpainter", params_path)
    metrics = train_and_report(section, Protocol.from_dict(params.get("protocol") or {}), accelerator, devices, afresh,
                               init_checkpoint, tracking_uri, progress, artifact_location)
    if metrics:
        print(f"inpainter: {metrics['num_parameters']:,} parameters, {metrics['epochs']} epochs in "
              f"{metrics['train_seconds']:.0f} s; val precision {metrics['val_precision']:.3f}, recall "
              f"{metrics['val_recall']:.3f}, F1 {metrics['val_f1']:.3f} at tau={metrics['threshold']} -> {MODELS.inpainter}")
    return metrics


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument("--accelerator", default=None, help="Lightning accelerator (cpu, gpu, auto) [params]")
    parser.add_argument("--devices", default=None, help="Lightning devices (1, 2, auto) [params]")
    parser.add_argument("--afresh", action="store_true",
                        help="train from the start even if checkpoints/inpainter holds a run of the same settings and data")
    parser.add_argument("--init-checkpoint", default=None, help="official Big-LaMa checkpoint, or an inpainter.pt export, to start from")
    parser.add_argument("--tracking-uri", default=None, help="MLflow store [default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db]")
    parser.add_argument("--progress", action="store_true", help="show Lightning's progress bar")
    args = parser.parse_args()
    devices = int(args.devices) if args.devices and args.devices.isdigit() else args.devices
    run_stage_main(main, args.params, args.accelerator, devices, args.afresh, args.init_checkpoint, args.tracking_uri, args.progress)
