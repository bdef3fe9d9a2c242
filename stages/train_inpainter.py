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

from pipeline.common.paths import MODELS
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.train_inpainter import Settings, train_and_report


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
    metrics = train_and_report(
        read_stage(params_path, "train_inpainter", Settings),
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
