"""Tests of what every training run shares (pipeline/training/run_setup.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from pipeline.common.config import check_value
from pipeline.training.lightning_run import RunOptions
from pipeline.training.run_setup import (
    DEVICES,
    PREVIOUS_CHECKPOINTS,
    check_accelerator,
    cpu_model,
    fresh_checkpoints,
    torch_threads,
    training_host,
)


def file_bytes(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file()}


def test_fresh_checkpoints_set_old_ones_aside_and_restore_them_on_failure(tmp_path):
    out = tmp_path / "ckpts"
    out.mkdir()
    (out / "best.ckpt").write_text("old best")
    (out / "last.ckpt").write_text("old last")
    (out / "inpainter.pt").write_text("export")
    with fresh_checkpoints(out):  # success: the old checkpoints are gone, other files stay
        assert not list(out.glob("*.ckpt")) and (out / PREVIOUS_CHECKPOINTS / "best.ckpt").is_file()
        (out / "last.ckpt").write_text("new last")
    assert file_bytes(out) == {"inpainter.pt": b"export", "last.ckpt": b"new last"}
    assert not (out / PREVIOUS_CHECKPOINTS).exists()

    (out / "best.ckpt").write_text("old best")
    with pytest.raises(KeyboardInterrupt), fresh_checkpoints(out):  # fails before writing any: old ones come back
        raise KeyboardInterrupt
    assert file_bytes(out) == {"best.ckpt": b"old best", "inpainter.pt": b"export", "last.ckpt": b"new last"}
    assert not (out / PREVIOUS_CHECKPOINTS).exists()

    with pytest.raises(RuntimeError), pytest.warns(UserWarning, match="continue with --resume.*previous_checkpoints"):
        with fresh_checkpoints(out):  # fails after writing one: the new one stays (resumable), the old ones aside
            (out / "last.ckpt").write_text("crashed run")
            raise RuntimeError("out of memory")
    assert file_bytes(out) == {"inpainter.pt": b"export", "last.ckpt": b"crashed run"}
    assert file_bytes(out / PREVIOUS_CHECKPOINTS) == {"best.ckpt": b"old best", "last.ckpt": b"new last"}

    with fresh_checkpoints(out, fresh=False):  # a resumed run leaves everything in place
        pass
    assert file_bytes(out) == {"inpainter.pt": b"export", "last.ckpt": b"crashed run"}


@pytest.mark.parametrize(
    "accelerator, devices, message",
    [
        ("foo", 1, r"accelerator 'foo': unknown; use one of auto, cpu, cuda, gpu, mps, tpu \(available here: .*cpu"),
        ("CPU", 1, r"accelerator 'CPU': unknown"),
        (
            "cpu",
            0,
            r"^devices: must be a number of devices >= 1, a list of device indices, 'auto' \(all\), "
            r"or one of those as text such as '0,1', got 0$",
        ),
        ("cpu", "0", r"^devices: must be .*, got '0'$"),
        ("cpu", [], r"^devices: must be .*, got \[\]$"),
        ("cpu", "1,-1", r"^devices: must be .*, got '1,-1'$"),
        ("auto", -1, r"^devices: must be a number of devices >= 1, .*got -1$"),
        ("cpu", "two", r"^devices: must be .*, got 'two'$"),
        ("cpu", True, r"^devices: must be .*, got True$"),
        ("cpu", [0, 1], r"devices \[0, 1\]: the cpu accelerator takes a number of processes"),
    ],
)
def test_training_settings_are_checked(accelerator, devices, message):
    with pytest.raises(ValueError, match=message):
        check_accelerator(accelerator, devices)


@pytest.mark.parametrize(
    "devices, kept",
    [(1, 1), (np.int64(2), 2), ([0, 1], [0, 1]), ((0,), [0]), ("auto", "auto"), ("0,1", "0,1"), ("2", "2")],
)
def test_devices_take_every_shape_lightning_reads(devices, kept):
    """A count, device indices or "auto", or one of those as the command line's text (kept as given:
    Lightning reads it)."""
    assert check_value(DEVICES, devices, "train_planner.devices") == kept


@pytest.mark.parametrize("devices", [-1, "-1", 0])
def test_minus_one_devices_are_refused_by_the_check_not_by_lightning_later(devices):
    with pytest.raises(ValueError, match=r"train_planner.devices: must be a number of devices >= 1, .*'auto' \(all\)"):
        check_value(DEVICES, devices, "train_planner.devices")


def test_run_options_are_checked_once_with_one_line_errors(tmp_path):
    run = RunOptions.from_dict({"out_dir": str(tmp_path), "devices": "1"})
    assert run.out_dir == tmp_path and run.checkpoint_dir == tmp_path and run.devices == "1" and run.mlflow
    other = RunOptions.from_dict({"out_dir": tmp_path, "checkpoint_dir": tmp_path / "c"})
    assert other.checkpoint_dir == tmp_path / "c"
    for values, message in (
        ({"devices": 1.5}, "devices: must be a number of devices >= 1, "),
        ({"resume": "yes"}, "resume: must be true or false, got 'yes'"),
        ({"experiment": ""}, "experiment: must be a non-empty string (an MLflow experiment)"),
        ({"accelerator": "foo"}, "accelerator 'foo': unknown; use one of "),
        ({"epochs": 3}, "epochs: unknown setting (known: out_dir, checkpoint_dir, "),
    ):
        with pytest.raises(ValueError) as refused:
            RunOptions.from_dict({"out_dir": tmp_path, **values})
        assert str(refused.value).startswith(message) and "\n" not in str(refused.value), str(refused.value)


def test_unavailable_accelerators_are_named():
    from lightning.pytorch.accelerators import XLAAccelerator

    for accelerator, devices in (("cpu", 1), ("cpu", "2"), ("auto", "auto"), ("auto", 1)):
        check_accelerator(accelerator, devices)  # accepted
    if not torch.cuda.is_available():
        for name in ("gpu", "cuda"):
            with pytest.raises(
                ValueError, match=rf"accelerator '{name}': no (CUDA )?GPU is visible to torch .*use cpu or auto"
            ):
                check_accelerator(name, 1)
    else:
        with pytest.raises(ValueError, match=r"devices 99: torch sees \d+ CUDA GPU"):
            check_accelerator("gpu", 99)
    if not XLAAccelerator.is_available():
        with pytest.raises(ValueError, match=r"accelerator 'tpu': not available on this machine .*use cpu or auto"):
            check_accelerator("tpu", 1)


def test_torch_threads_are_restored_even_when_the_block_fails():
    before = torch.get_num_threads()
    with torch_threads(None):
        assert torch.get_num_threads() == before
    other = 1 if before != 1 else 2
    with pytest.raises(RuntimeError), torch_threads(other):
        assert torch.get_num_threads() == other
        raise RuntimeError("training failed")
    assert torch.get_num_threads() == before


def test_training_host_names_the_torch_build_kernels_and_threads_in_use():
    other = 1 if torch.get_num_threads() != 1 else 2
    with torch_threads(other):
        host = training_host()
    name, flags = cpu_model()
    assert host == {
        "torch": torch.__version__,
        "cpu": name,
        "cpu_flags": flags,
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "threads": other,
        "device": "cpu",
    }


def test_cpu_model_reads_the_name_and_the_matmul_flags_of_the_first_processor():
    cpuinfo = (
        "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: Intel(R) Xeon(R) Platinum 8480+\n"
        "flags\t\t: fpu sse avx2 avx512f amx_bf16 amx_tile\n\n"
        "processor\t: 1\nmodel name\t: something else\nflags\t\t: fpu\n"
    )
    assert cpu_model(cpuinfo) == ("Intel(R) Xeon(R) Platinum 8480+", "avx2 avx512f amx_tile amx_bf16")
    assert cpu_model("processor\t: 0\nflags\t: sse\n")[1] == ""
