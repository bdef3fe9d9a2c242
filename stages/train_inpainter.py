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

import pydantic

from pipeline.common.config import Section, fields_of, maybe, text, whole
from pipeline.common.paths import MODELS
from pipeline.models.configuration_inpainter import InpainterConfig
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.training.inpainter import TrainConfig
from pipeline.training.run_setup import DEVICES
from pipeline.workflows.train_inpainter import train_and_report

# The `train_inpainter` section: TrainConfig's fields and the run's own settings side by side.
# Every key may be left out: the stage trains with TrainConfig's and InpainterConfig's defaults.
Settings = pydantic.create_model(
    "Settings",
    __base__=Section,
    __module__=__name__,
    __doc__="The `train_inpainter` section of params.yaml.",
    **fields_of(TrainConfig),
    model=(InpainterConfig, InpainterConfig()),  # its fields, or big_lama: true with overrides
    accelerator=(maybe(text(note="Lightning's accelerator: cpu, gpu, auto"), "cpu"), None),
    devices=(maybe(DEVICES, "1"), None),
    num_nodes=(maybe(whole(1, note="nodes of a multi-node DDP run"), "1"), None),
    threads=(maybe(whole(0, note="0: torch's default"), "torch's default"), None),
    init_checkpoint=(maybe(text(note="a Big-LaMa checkpoint or an inpainter export"), "random weights"), None),
    experiment=(maybe(text(note="an MLflow experiment"), "inpainter"), None),
)


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
    section = read_stage(params_path, "train_inpainter", Settings)
    metrics = train_and_report(
        section,
        read_protocol(params_path),
        accelerator,
        devices,
        afresh,
        init_checkpoint,
        tracking_uri,
        progress,
        artifact_location,
    )
    if metrics:
        print(
            f"inpainter: {metrics['num_parameters']:,} parameters, {metrics['epochs']} epochs in "
            f"{metrics['train_seconds']:.0f} s; val precision {metrics['val_precision']:.3f}, recall "
            f"{metrics['val_recall']:.3f}, F1 {metrics['val_f1']:.3f} at tau={metrics['threshold']} -> {MODELS.inpainter}"
        )
    return metrics


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument("--accelerator", default=None, help="Lightning accelerator (cpu, gpu, auto) [params]")
    parser.add_argument("--devices", default=None, help="Lightning devices (1, 2, auto) [params]")
    parser.add_argument(
        "--afresh",
        action="store_true",
        help="train from the start even if checkpoints/inpainter holds a run of the same settings and data",
    )
    parser.add_argument(
        "--init-checkpoint", default=None, help="official Big-LaMa checkpoint, or an inpainter.pt export, to start from"
    )
    parser.add_argument(
        "--tracking-uri", default=None, help="MLflow store [default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db]"
    )
    parser.add_argument("--progress", action="store_true", help="show Lightning's progress bar")
    args = parser.parse_args()
    devices = int(args.devices) if args.devices and args.devices.isdigit() else args.devices
    run_stage_main(
        main,
        args.params,
        args.accelerator,
        devices,
        args.afresh,
        args.init_checkpoint,
        args.tracking_uri,
        args.progress,
    )
