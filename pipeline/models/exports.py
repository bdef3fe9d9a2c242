"""Reading exported model files: tensors and plain containers only, with one-line errors.

`weights_only=True` refuses pickled code, so a file from elsewhere cannot run anything on
load; a file that is not a model export fails with a ValueError naming it, not a traceback.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import Any

import torch


def require_file(path: str | Path, what: str) -> Path:
    """`path`, or FileNotFoundError saying whether nothing or a folder is there ("what": the expected file)."""
    path = Path(path)
    if path.is_dir():
        raise FileNotFoundError(f"{path}: a folder, not a file (expected {what})")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: file not found (expected {what})")
    return path


def read_weights_file(path: str | Path, what: str, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """The dict saved in `path` ("what" names the expected file, article included, for errors).

    FileNotFoundError if absent; ValueError if it is not a `torch.save` archive, holds pickled
    objects beyond tensors and plain containers, or holds something other than a dict.
    """
    path = require_file(path, what)
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path}: not {what} (not a file written by torch.save)")
    try:
        payload = torch.load(path, map_location=map_location, weights_only=True)
    except Exception:  # noqa: BLE001 - a weights-only refusal or a damaged archive
        raise ValueError(
            f"{path}: not {what} (it is damaged or holds pickled objects beyond tensors and plain "
            "containers, which are refused because loading them would run code from the file)"
        ) from None
    if not isinstance(payload, dict):
        raise ValueError(f"{path}: not {what} (it holds a {type(payload).__name__}, not a dict)")
    return payload


def write_weights_file(payload: dict[str, Any], path: str | Path) -> Path:
    """`torch.save(payload)` to `path`, atomically: a reader never sees half a file, and two
    processes writing the same path (a multi-GPU run) never share a temporary file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)
    return path


INPAINTER_FORMAT = "guide-inpainter/1"  # the `format` key of an inpainter.pt export


def export_kind(payload: dict[str, Any]) -> str | None:
    """Which of this project's exports a payload is ("inpainter" or "policy"), else None: so that
    a file given in the other's place is named for what it is, not by its unknown config keys."""
    if payload.get("format") == INPAINTER_FORMAT:
        return "inpainter"
    config = payload.get("config")
    if isinstance(config, dict) and {"horizon", "d_model"} <= set(config):
        return "policy"
    return None
