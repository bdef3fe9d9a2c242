"""What every training run shares: the shape of its devices and the accelerators this machine has,
the Lightning trainer, old checkpoints set aside, checkpoints written atomically and resumed only
for the same settings and data, torch's CPU threads and the MLflow logger.

The inpainter (Stage I) and the diffusion planner (Stage II) train the same way: settings
are checked before a file is touched or an MLflow run is made, Lightning's refusals become
one-line ValueErrors, and a fresh run never loses the previous run's checkpoints until it has
its own.
"""

from __future__ import annotations

import json
import os
import platform
import random
import shutil
import warnings
from contextlib import contextmanager
from datetime import timedelta
from pathlib import Path
from typing import Any, Iterator, Optional, Sequence, cast

import lightning as L
import numpy as np
import torch

from pipeline.common.atomic import atomic_file, atomic_write_json
from pipeline.common.config import any_of, check_value, list_of, satisfies, text, whole
from pipeline.common.mlflow_store import import_mlflow, resolve_tracking_uri

LAST_CKPT = "last.ckpt"
RUN_RECORD = "run.json"


def max_time(max_minutes: Optional[float]) -> Optional[timedelta]:
    """Lightning's `max_time` for a `max_minutes` setting (None: no cap)."""
    return None if max_minutes is None else timedelta(minutes=float(max_minutes))


def one_line(error: BaseException, limit: int = 200) -> str:
    """An exception as one short line (its first line, or its type when it has no message)."""
    lines = str(error).strip().splitlines()
    text = lines[0].strip() if lines else type(error).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _read_devices_text(value: str) -> int | list[int] | str:
    """A command line's devices ('2', '-1', '0,1', 'auto') as the value it stands for; the text
    itself when it reads as none (the shapes of DEVICES refuse it then)."""
    value = value.strip()
    if value == "auto":
        return value
    try:
        return int(value)
    except ValueError:
        pass
    try:
        return [int(part) for part in value.split(",") if part.strip()] or value
    except ValueError:
        return value


_DEVICE_SHAPES = (whole(1), list_of(whole(0)), text(("auto",)))
_DEVICE_VALUE = any_of(*_DEVICE_SHAPES)


def _devices_text(value: str) -> None:
    check_value(_DEVICE_VALUE, _read_devices_text(value), "devices")


# Lightning's `devices`: a number of devices per node, a list of device indices or "auto", or the
# same as the text a command line gives ("2", "0,1"). Lightning's -1 ("all") is refused here, where
# it would be refused by Lightning on a CPU only after the stage started: "auto" takes every device.
# Whether this machine has them is `check_accelerator`'s question.
DEVICES = any_of(
    *_DEVICE_SHAPES,
    satisfies(_devices_text, "devices as text", kind=str),
    description="a number of devices >= 1, a list of device indices, 'auto' (all), "
    "or one of those as text such as '0,1'",
)


def _parse_devices(devices: Any) -> int | list[int] | str:
    """Lightning's `devices` as a count, a list of indices or "auto" (text read); a ValueError
    `devices: must be ..., got ...` for a value of no DEVICES shape."""
    devices = check_value(DEVICES, devices, "devices")
    return _read_devices_text(devices) if isinstance(devices, str) else devices


def check_accelerator(accelerator: Any, devices: Any) -> None:
    """ValueError (one line, naming the option and what is available) for training settings
    Lightning would refuse: an unknown accelerator or one this machine lacks, devices of no DEVICES
    shape (-1 among them), device indices for the cpu, or more CUDA GPUs than torch sees."""
    from lightning.pytorch.accelerators import Accelerator, AcceleratorRegistry

    names = sorted({"auto", "gpu", *AcceleratorRegistry.available_accelerators()})
    gpu = torch.cuda.is_available() or torch.backends.mps.is_available()
    kind = accelerator
    if isinstance(accelerator, Accelerator):
        kind = None
    elif not isinstance(accelerator, str) or accelerator not in names:
        usable = ["auto", "cpu"] + [
            n for n in names if n not in ("auto", "cpu", "gpu") and AcceleratorRegistry[n]["accelerator"].is_available()
        ]
        raise ValueError(
            f"accelerator {accelerator!r}: unknown; use one of {', '.join(names)} "
            f"(available here: {', '.join(usable + (['gpu'] if gpu else []))})"
        )
    elif accelerator == "gpu":
        if not gpu:
            raise ValueError(
                "accelerator 'gpu': no GPU is visible to torch (torch.cuda.is_available() is False); use cpu or auto"
            )
        kind = "cuda" if torch.cuda.is_available() else "mps"
    elif accelerator == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            "accelerator 'cuda': no CUDA GPU is visible to torch (torch.cuda.is_available() is False); use cpu or auto"
        )
    elif (
        accelerator not in ("auto", "cpu", "cuda")
        and not AcceleratorRegistry[accelerator]["accelerator"].is_available()
    ):
        hint = {"mps": "torch.backends.mps.is_available() is False", "tpu": "torch_xla is missing or finds no TPU"}.get(
            accelerator, ""
        )
        raise ValueError(
            f"accelerator {accelerator!r}: not available on this machine{f' ({hint})' if hint else ''}; use cpu or auto"
        )
    if accelerator == "auto" and not gpu and not AcceleratorRegistry["tpu"]["accelerator"].is_available():
        kind = "cpu"  # what Lightning picks here
    wanted = _parse_devices(devices)
    if isinstance(wanted, list) and kind == "cpu":
        raise ValueError(f"devices {devices!r}: the cpu accelerator takes a number of processes, not device indices")
    if kind == "cuda":
        count = torch.cuda.device_count()
        asked = wanted if isinstance(wanted, int) else (max(wanted) + 1 if isinstance(wanted, list) else 0)
        if asked > count:
            raise ValueError(f"devices {devices!r}: torch sees {count} CUDA GPU{'s' if count != 1 else ''} here")


def make_trainer(**options: Any) -> "L.Trainer":
    """`L.Trainer(**options)`, with Lightning's refusal of the accelerator or devices as a one-line ValueError."""
    from lightning.fabric.utilities.exceptions import MisconfigurationException

    try:
        return L.Trainer(**options)
    except MisconfigurationException as error:
        raise ValueError(
            f"training settings accelerator={options.get('accelerator')!r}, "
            f"devices={options.get('devices')!r}: {one_line(error)}"
        ) from None


def atomic_checkpoint_io() -> Any:
    """Lightning's checkpoint writer, with each file written under a temporary name and renamed:
    a kill while `last.ckpt` is written leaves the previous epoch's, never a truncated one."""
    from lightning.fabric.plugins.io.torch_io import TorchCheckpointIO

    class AtomicCheckpointIO(TorchCheckpointIO):
        def save_checkpoint(self, checkpoint: dict[str, Any], path: Any, storage_options: Any = None) -> None:
            with atomic_file(path) as tmp:
                super().save_checkpoint(checkpoint, tmp, storage_options)

    return AtomicCheckpointIO()


Generators = Sequence["torch.Generator | np.random.Generator"]


def random_states(generators: Generators = ()) -> dict[str, Any]:
    """The random generators' states at a checkpoint: torch's, numpy's and Python's global ones
    (augmentation and diffusion noise draw from them) and `generators` (a data loader's shuffle,
    a data set's augmentation), so that a resumed run draws what an uninterrupted one would and
    trains the same weights."""
    kind, keys, position, has_gauss, gauss = cast(
        tuple[str, np.ndarray, int, int, float], np.random.get_state()
    )  # plain values: a weights-only load reads them
    return {
        "torch": torch.get_rng_state(),
        "numpy": [kind, torch.from_numpy(keys.astype(np.int64)), position, has_gauss, gauss],
        "python": random.getstate(),
        "generators": [g.get_state() if isinstance(g, torch.Generator) else g.bit_generator.state for g in generators],
    }


def restore_random_states(states: dict[str, Any] | None, generators: Generators = ()) -> None:
    """Put back what `random_states` saved (nothing for a checkpoint that has none)."""
    if not states:
        return
    torch.set_rng_state(states["torch"])
    kind, keys, position, has_gauss, gauss = states["numpy"]
    np.random.set_state((kind, keys.numpy().astype(np.uint32), position, has_gauss, gauss))
    random.setstate(states["python"])
    for generator, state in zip(generators, states["generators"]):
        if isinstance(generator, torch.Generator):
            generator.set_state(state)
        else:
            generator.bit_generator.state = state


def resume_point(folder: str | Path, fingerprint: str, what: str) -> tuple[str, int] | None:
    """(`folder/last.ckpt`, the epochs it finished) when `folder/run.json` says it was made with
    `fingerprint` (the same settings and data), else None; one line says which, when there is a
    checkpoint to decide on."""
    folder = Path(folder)
    last, record = folder / LAST_CKPT, folder / RUN_RECORD
    if not last.is_file():
        return None
    try:
        recorded = json.loads(record.read_text()).get("fingerprint") if record.is_file() else None
    except (OSError, ValueError):
        recorded = None
    if recorded != fingerprint:
        print(f"{what}: {last} was made with other settings or data: training afresh")
        return None
    try:
        state = torch.load(last, map_location="cpu", weights_only=False)
        finished = int(state["epoch"]) + 1  # Lightning saves at the end of an epoch, numbered from 0
    except Exception as error:  # noqa: BLE001 - an unreadable checkpoint means: start afresh
        print(f"{what}: {last} is unreadable ({type(error).__name__}): training afresh")
        return None
    print(f"{what}: resuming from {last} after {finished} epoch{'s' if finished != 1 else ''}")
    return str(last), finished


def start_afresh(folder: str | Path, fingerprint: str) -> None:
    """Drop the checkpoints of other settings or data in `folder`, then record `fingerprint` as
    the one the checkpoints written from now on are made with (in that order: a kill between the
    two leaves no checkpoint to resume from)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("*.ckpt"):
        old.unlink()
    shutil.rmtree(folder / PREVIOUS_CHECKPOINTS, ignore_errors=True)
    atomic_write_json(folder / RUN_RECORD, {"fingerprint": fingerprint})


PREVIOUS_CHECKPOINTS = "previous_checkpoints"


@contextmanager
def quiet_checkpoint_folder() -> Iterator[None]:
    """Lightning warns when its checkpoint folder is not empty; ours holds the run's record
    (`run.json`) and, when resuming, the checkpoints it resumes from, by design."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"Checkpoint directory .* exists and is not empty")
        yield


@contextmanager
def fresh_checkpoints(out_dir: Path, fresh: bool = True) -> Iterator[None]:
    """Around a fresh run's `fit`: set the previous run's `*.ckpt` aside, and drop them once it succeeds.

    Old `best` / `last` files would confuse ModelCheckpoint, but deleting them up front lost a
    good model whenever the new run crashed. If `fit` fails (an exception, Ctrl-C) before it
    wrote a checkpoint, the old ones are put back; if it wrote some (resumable with --resume),
    the old ones stay in `out_dir/previous_checkpoints/` and a warning says so. Only the
    rank-zero process moves files (the others of a multi-GPU run re-enter this code).
    """
    if not fresh or os.environ.get("LOCAL_RANK", "0") != "0" or os.environ.get("NODE_RANK", "0") != "0":
        yield
        return
    aside = out_dir / PREVIOUS_CHECKPOINTS
    stale = sorted(out_dir.glob("*.ckpt"))
    if stale:
        shutil.rmtree(aside, ignore_errors=True)
        aside.mkdir()
        for path in stale:
            path.replace(aside / path.name)
    try:
        yield
    except BaseException:
        if stale and not any(out_dir.glob("*.ckpt")):
            for path in aside.glob("*.ckpt"):
                path.replace(out_dir / path.name)
            shutil.rmtree(aside, ignore_errors=True)
        elif stale:
            warnings.warn(
                f"training stopped after writing new checkpoints in {out_dir} (continue with --resume); "
                f"the previous run's are in {aside}",
                stacklevel=3,
            )
        raise
    shutil.rmtree(aside, ignore_errors=True)


@contextmanager
def torch_threads(count: Optional[int]) -> Iterator[None]:
    """torch's CPU threads set to `count` (None or 0: unchanged) for the block, then restored."""
    previous = torch.get_num_threads()
    if count:
        torch.set_num_threads(int(count))
    try:
        yield
    finally:
        torch.set_num_threads(previous)


# CPU features that change which matrix kernels oneDNN and MKL run (and so how sums round).
MATMUL_FLAGS = ("avx2", "avx512f", "avx512_bf16", "avx512_vnni", "amx_tile", "amx_bf16")


def cpu_model(cpuinfo: str | None = None) -> tuple[str, str]:
    """(the CPU's model name, the MATMUL_FLAGS it has, space-separated) from /proc/cpuinfo;
    (platform.processor(), "") where there is none (macOS, Windows)."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
        except OSError:
            return platform.processor(), ""
    fields: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())  # the first processor's
    flags = set(fields.get("flags", "").split())
    return fields.get("model name", platform.processor()), " ".join(f for f in MATMUL_FLAGS if f in flags)


def training_host(device: torch.device | str = "cpu") -> dict[str, Any]:
    """What trained weights depend on beyond code, data and seeds: the torch build, the CPU
    and the kernels torch dispatches to on it, its thread count and the device.

    The same code, data and seeds can train other weights on a CPU with other kernels (AMX
    or not, say), so every export and stage metrics file says where it was made, and a user
    comparing figures can see why.
    """
    device = torch.device(device)
    name, flags = cpu_model()
    host: dict[str, Any] = {
        "torch": str(torch.__version__),  # a str subclass, which a weights-only load refuses
        "cpu": name,
        "cpu_flags": flags,
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "threads": torch.get_num_threads(),
        "device": device.type,
    }
    if device.type == "cuda" and torch.cuda.is_available():
        host["device"] = torch.cuda.get_device_name(device)
    return host


def mlflow_logger(
    experiment_name: str,
    run_name: Optional[str],
    tracking_uri: Optional[str],
    artifact_location: Optional[str] = None,
    run_id: Optional[str] = None,
) -> Any:
    """Lightning's MLFlowLogger on `tracking_uri` (default $MLFLOW_TRACKING_URI or sqlite:///mlflow.db):
    Lightning's own default is the ./mlruns file store, which MLflow 3 refuses. With `run_id`, it
    logs on into that run (a resumed training)."""
    from lightning.pytorch.loggers import MLFlowLogger
    from lightning.pytorch.utilities import rank_zero_only

    import_mlflow()  # telemetry off before Lightning imports it

    class ResumedMLFlowLogger(MLFlowLogger):
        """Logs on into an existing run: a setting the resumed training changed (a longer
        max_epochs) is kept as the tag `resumed.<key>`, since MLflow never changes a param."""

        @rank_zero_only  # the other ranks of a multi-process run hold no MLflow client
        def log_hyperparams(self, params: Any) -> None:
            from lightning.fabric.utilities.logger import _convert_params, _flatten_dict

            flat = _flatten_dict(_convert_params(params))
            logged = self.experiment.get_run(self.run_id).data.params
            changed = {k: v for k, v in flat.items() if k in logged and logged[k] != str(v)[:250]}
            for key, value in changed.items():
                self.experiment.set_tag(self.run_id, f"resumed.{key}", str(value)[:5000])
            fresh = {k: v for k, v in flat.items() if k not in logged}
            if fresh:
                super().log_hyperparams(fresh)

    kind = MLFlowLogger if run_id is None else ResumedMLFlowLogger
    return kind(
        experiment_name=experiment_name,
        run_name=run_name,
        tracking_uri=resolve_tracking_uri(tracking_uri),
        artifact_location=artifact_location,
        run_id=run_id,
    )


def log_export(logger: Any, export_path: Path, seconds: float, num_parameters: int, host: dict[str, Any]) -> None:
    """What both trainings log to their MLflow run once the export is written: training time,
    size, where the weights were made (tags `trained_on.*`) and the export as an artifact."""
    logger.experiment.log_metric(logger.run_id, "train_seconds", seconds)
    logger.experiment.log_metric(logger.run_id, "num_parameters", num_parameters)
    for key, value in host.items():
        logger.experiment.set_tag(logger.run_id, f"trained_on.{key}", value)
    logger.experiment.log_artifact(logger.run_id, str(export_path))
