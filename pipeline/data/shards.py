"""Crash-safe sharded data sets: deterministic shards, a manifest, and parallel backends.

A data set is a folder of shards `shard_00000.npz, shard_00001.npz, ...` plus `manifest.json`.
Shard k is a pure function of (params, seed, k) and the code. Shards are made in a work folder
under `checkpoints/`, outside the DVC output (DVC deletes an output before it reruns its
stage), each with a record of the fingerprint (params + code) that made it; an interrupted
collection resumes by keeping the finished shards whose record matches. Once every shard is
there, the data set folder is published as a whole (`pipeline.common.atomic.atomic_folder`),
its shards hard links to the work folder's (copies where links are impossible), the manifest
written last. The data set holds only what the data are: no fingerprint, no commit, no
time, so the same params give the same bytes on any machine and with any commit of code
that makes the same data.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any, Callable, Sequence, cast

import numpy as np

from pipeline.common.atomic import atomic_folder, atomic_write_bytes, atomic_write_json
from pipeline.common.executor import resolve_backend, run_tasks
from pipeline.common.fingerprints import settings_digest, source_digest

MANIFEST = "manifest.json"


@dataclass(frozen=True)
class ShardJob:
    """Everything a worker needs to write shard `index` of a data set (into `out_dir`, the work folder)."""

    index: int
    out_dir: str
    fingerprint: str
    params: dict[str, Any]


def fingerprint(params: dict[str, Any], sources: Sequence[str] | None = None) -> str:
    """A short stable hash of what determines a data set's content: parameters and code."""
    return settings_digest({"params": params, "source": source_digest(sources)})


def shard_path(out_dir: str | Path, index: int) -> Path:
    return Path(out_dir) / f"shard_{index:05d}.npz"


def write_shard(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    """Write a compressed shard atomically: a reader never sees half a file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with tmp.open("wb") as handle:
        np.savez_compressed(handle, **cast(dict[str, Any], arrays))
    os.replace(tmp, path)


def read_shard(path: str | Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


def _record_path(path: Path) -> Path:
    return path.with_suffix(".json")


def shard_is_current(path: Path, expected_fingerprint: str) -> bool:
    """A finished shard in the work folder is kept only if its record names the same fingerprint and it is readable."""
    record = _record_path(path)
    if not path.is_file() or not record.is_file():
        return False
    try:
        if json.loads(record.read_text()).get("fingerprint") != expected_fingerprint:
            return False
        with np.load(path, allow_pickle=False) as data:
            data.files  # noqa: B018 - a readable zip directory
        return True
    except Exception:  # a corrupt file from an older crash: redo it
        return False


def code_version() -> str:
    """The git commit of the code that made the data (or 'unknown' outside a checkout)."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).resolve().parent,
        )
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            cwd=Path(__file__).resolve().parent,
        ).stdout.strip()
        return out.stdout.strip() + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_shards(
    make_shard: Callable[[ShardJob], dict[str, Any]],
    shard_count: int,
    out_dir: str | Path,
    params: dict[str, Any],
    workers: int = 1,
    backend: str | None = None,
    description: str = "shards",
    progress: bool = True,
    sources: Sequence[str] | None = None,
    work_dir: str | Path | None = None,
    inputs: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Make every missing shard (in parallel) in `work_dir`, then publish the data set at `out_dir`;
    returns its manifest with this run's provenance.

    `make_shard(job)` writes `shard_path(job.out_dir, job.index)` (its counts as `summary_*`
    arrays) into a private folder of the machine that runs it; the shard comes back as the task's
    result (`shard_bytes`) and this process writes it into the work folder (default: `out_dir`
    with `.work` appended, beside it), on either engine (`pipeline.common.executor`; `backend`
    None: $GUIDE_BACKEND, else process). Shards from other params or code and stray temporaries
    are removed from the work folder first.
    `sources` names the library files whose code the shards depend on (see `fingerprint`).
    `inputs` is what else they depend on, such as the digests of the models a collection runs:
    it enters the fingerprint only, since those bytes can differ where the data do not (an export
    records its training time).

    The manifest holds only what the data are (params, shards, totals), so the data set's
    bytes, and DVC's hash of them, do not change with the code's commit or with a resume. The
    returned dict adds `code_version` and `made_this_run` (the shard indices this run made)
    for the caller's run summary.
    """
    backend = resolve_backend(backend)  # checked before any shard on disk is touched
    out_dir = Path(out_dir)
    work = Path(work_dir) if work_dir is not None else out_dir.with_name(out_dir.name + ".work")
    work.mkdir(parents=True, exist_ok=True)
    fp = fingerprint(params if inputs is None else {"params": params, "inputs": inputs}, sources)
    for stray in work.glob(".*"):
        shutil.rmtree(stray) if stray.is_dir() else stray.unlink()
    for old in work.glob("shard_*.npz"):
        index = int(old.stem.split("_")[1])
        if index >= shard_count or not shard_is_current(old, fp):
            old.unlink()
            _record_path(old).unlink(missing_ok=True)
    for record in work.glob("shard_*.json"):
        if not record.with_suffix(".npz").is_file():
            record.unlink()
    todo = [k for k in range(shard_count) if not shard_path(work, k).is_file()]
    if len(todo) < shard_count:
        print(f"{description}: {shard_count - len(todo)} of {shard_count} kept from an earlier run ({work})")

    def finished(position: int, shard: bytes) -> None:  # the record last: a shard without one is redone
        path = shard_path(work, todo[position])
        atomic_write_bytes(path, shard)
        atomic_write_json(_record_path(path), {"fingerprint": fp})

    jobs = [ShardJob(k, "", fp, params) for k in todo]
    run_tasks(
        partial(shard_bytes, make_shard),
        jobs,
        workers,
        description,
        "shard",
        backend=backend,
        progress=progress,
        on_result=finished,
        collect=False,
    )
    # Counts read back from every shard file, made now or earlier, so a resume writes the same manifest.
    shards = [{"file": shard_path(work, k).name, **summarise_shard(shard_path(work, k))} for k in range(shard_count)]
    manifest = {"params": params, "shards": shards, "totals": _totals(shards)}
    with atomic_folder(out_dir) as folder:
        for k in range(shard_count):
            _link_or_copy(shard_path(work, k), shard_path(folder, k))
        (folder / MANIFEST).write_text(json.dumps(manifest, indent=2, default=str) + "\n")
    return {**manifest, "code_version": code_version(), "made_this_run": todo}


def shard_bytes(make_shard: Callable[[ShardJob], Any], job: ShardJob) -> bytes:
    """The bytes of the shard `make_shard` writes for `job`, made in a private folder of whichever
    machine runs it: the shard travels back as the task's result, not through a shared disk."""
    with tempfile.TemporaryDirectory(prefix="guide-shard-") as folder:
        make_shard(replace(job, out_dir=folder))
        return shard_path(folder, job.index).read_bytes()


def _link_or_copy(source: Path, target: Path) -> None:
    """`target` as a hard link to `source` (no second copy on disk), or a copy across file systems."""
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def summarise_shard(path: Path) -> dict[str, Any]:
    """Counts stored in a shard's `summary_*` arrays, and its size on disk."""
    with np.load(path, allow_pickle=False) as data:
        summary = {key[len("summary_") :]: int(data[key]) for key in data.files if key.startswith("summary_")}
    summary["bytes"] = path.stat().st_size
    return summary


def _totals(shards: Sequence[dict[str, Any]]) -> dict[str, int]:
    totals: dict[str, int] = {}
    for shard in shards:
        for key, value in shard.items():
            if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
                totals[key] = totals.get(key, 0) + int(value)
    return totals


def shard_count_for(requested: int, per_shard: int, what: str) -> int:
    """Whole shards that hold `requested` items; a note on stdout when that rounds the request up.

    Shards are the unit of resumption and parallelism, so a data set is a whole number of them.
    """
    if requested < 1 or per_shard < 1:
        raise ValueError(f"{what}: {requested} requested, {per_shard} per shard; both must be at least 1")
    count = -(-requested // per_shard)
    if count * per_shard != requested:
        print(
            f"note: {requested} {what} is not a multiple of {per_shard} per shard; "
            f"collecting {count} shards = {count * per_shard} {what}"
        )
    return count


def rate_per_minute(manifest: dict[str, Any], key: str, seconds: float) -> float | None:
    """Items of `key` made per minute by the run that returned `manifest` (`run_shards`; None if it made none)."""
    made = [manifest["shards"][k].get(key, 0) for k in manifest["made_this_run"]]
    if not made or seconds <= 0:
        return None
    return round(60.0 * sum(made) / seconds, 2)


def read_manifest(out_dir: str | Path) -> dict[str, Any]:
    """The manifest of a finished data set; a clear error if the collection never finished."""
    path = Path(out_dir) / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no manifest (the collection did not finish; rerun its stage)")
    return json.loads(path.read_text())
