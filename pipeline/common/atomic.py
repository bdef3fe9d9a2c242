"""Outputs that appear whole or not at all.

A stage can be killed at any moment (a dropped lease, SIGKILL). Every file and folder it
writes is therefore made under a hidden temporary name beside its final place and renamed
into place once complete: `os.replace` is atomic on one file system, so a reader (a later
stage, a resumed run, a user) sees the old version, the new one or nothing, never a part.

- `atomic_write_text` / `atomic_write_bytes` / `atomic_write_json`: small files in one call.
- `atomic_file(path)`: a temporary path with the same suffix (libraries that pick the format
  from the name, such as `cv2.imwrite` and `savefig`, still do) for writers that want a path.
- `atomic_folder(path)`: a temporary folder that replaces `path` as a whole on success.

A temporary left behind by a kill starts with "." and holds ".partial" in its name; the next
write to the same place removes it (`remove_partials`).
"""

from __future__ import annotations

import json
import os
import shutil
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

PARTIAL = ".partial"


def _partial_name(path: Path) -> Path:
    """`.name.partial-PID.suffix`: the whole name, so that `reports/benchmark.json`'s temporary and the
    `reports/benchmark` folder's never match each other; the suffix kept for writers that read it."""
    return path.with_name(f".{path.name}{PARTIAL}-{os.getpid()}{path.suffix}")


def remove_partials(path: str | Path) -> None:
    """Temporaries of `path` left by an earlier, killed writer."""
    path = Path(path)
    if path.parent.is_dir():
        for stray in path.parent.glob(f".{path.name}{PARTIAL}-*"):
            shutil.rmtree(stray) if stray.is_dir() and not stray.is_symlink() else stray.unlink(missing_ok=True)


@contextmanager
def atomic_file(path: str | Path) -> Iterator[Path]:
    """A temporary path to write; it replaces `path` when the block ends without an error."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_partials(path)
    tmp = _partial_name(path)
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"{tmp}: the writer made no file for {path}")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    with atomic_file(path) as tmp:
        with open(tmp, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | Path, value: Any, indent: int | None = 2) -> None:
    """`value` as JSON (with a final newline), written atomically."""
    atomic_write_text(path, json.dumps(value, indent=indent, default=str) + "\n")


@contextmanager
def atomic_folder(path: str | Path) -> Iterator[Path]:
    """A temporary folder to fill; on success it replaces `path` (and whatever `path` held) as a whole.

    Between removing the old folder and renaming the new one into place there is an instant
    with neither; a kill there leaves no output, which every stage treats as "not made yet".
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_partials(path)
    tmp = _partial_name(path)
    tmp.mkdir()
    try:
        yield tmp
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
