"""Crash-safe sharded data sets: deterministic shards, a manifest, and parallel backends.

A data set is a folder of shards `shard_00000.npz, shard_00001.npz, ...` plus `manifest.json`. Shard k is a
pure function of (params, seed, k) and the code, so an interrupted collection resumes by
skipping the shards already on disk whose recorded fingerprint (params + source) matches, and a shard file only ever
appears complete (written to a temp name, then renamed). The manifest is written last:
later stages read the manifest, never a folder listing.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import subprocess
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from tqdm import tqdm

MANIFEST = "manifest.json"


@dataclass(frozen=True)
class ShardJob:
    """Everything a worker needs to write shard `index` of a data set."""

    index: int
    out_dir: str
    fingerprint: str
    params: dict[str, Any]


def source_digest(sources: Sequence[str] | None = None) -> str:
    """A hash of the library's source: data made by other code is never resumed from.

    `sources` are the package-relative folders and files that determine the data (the whole
    package when None), so that editing an unrelated part does not throw a data set away.
    """
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]  # the pipeline package
    paths: set[Path] = set()
    for source in [""] if sources is None else sources:
        path = root / source
        paths.update(path.rglob("*.py") if path.is_dir() else [path])
    for path in sorted(paths):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def fingerprint(params: dict[str, Any], sources: Sequence[str] | None = None) -> str:
    """A short stable hash of what determines a data set's content: parameters and code."""
    payload = json.dumps(params, sort_keys=True, default=str) + source_digest(sources)
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


def shard_path(out_dir: str | Path, index: int) -> Path:
    return Path(out_dir) / f"shard_{index:05d}.npz"


def write_shard(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    """Write a compressed shard atomically: a reader never sees half a file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with tmp.open("wb") as handle:
        np.savez_compressed(handle, **arrays)
    os.replace(tmp, path)


def read_shard(path: str | Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


def shard_is_current(path: Path, expected_fingerprint: str) -> bool:
    """An existing shard is reused only if it is readable and was made with the same params."""
    if not path.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as data:
            return "fingerprint" in data.files and str(data["fingerprint"]) == expected_fingerprint
    except Exception:  # a corrupt file from an older crash: redo it
        return False


def code_version() -> str:
    """The git commit of the code that made the data (or 'unknown' outside a checkout)."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True,
            cwd=Path(__file__).resolve().parent,
        )
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True,
                               cwd=Path(__file__).resolve().parent).stdout.strip()
        return out.stdout.strip() + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_shards(
    make_shard: Callable[[ShardJob], dict[str, Any]],
    shard_count: int,
    out_dir: str | Path,
    params: dict[str, Any],
    workers: int = 1,
    backend: str = "process",
    description: str = "shards",
    progress: bool = True,
    sources: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Make every missing shard (in parallel), then write the manifest; returns it with this run's provenance.

    `make_shard(job)` writes `shard_path(job.out_dir, job.index)` (with a `fingerprint`
    array and its counts as `summary_*` arrays). Shards from other params and stray
    temp files are removed first, so the folder ends up holding exactly this data set.
    `sources` names the library files whose code the shards depend on (see `fingerprint`).

    The manifest on disk holds only what the data are (params, fingerprint, shards, totals),
    so the folder's bytes, and DVC's hash of it, do not change with the git commit or with
    a resume. The returned dict adds `code_version` and `made_this_run` (the shard indices
    this run made) for the caller's run summary.
    """
    if backend not in ("process", "ray"):  # checked before any shard on disk is touched
        raise ValueError(f"unknown backend {backend!r}: use 'process' or 'ray'")
    if backend == "ray" and importlib.util.find_spec("ray") is None:
        raise ValueError("backend 'ray' needs Ray, which is not installed: pip install '.[ray]' (or use backend: process)")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fp = fingerprint(params, sources)
    manifest_path = out_dir / MANIFEST
    if manifest_path.exists():
        manifest_path.unlink()  # stale until this run finishes
    for stray in out_dir.glob(".*.tmp"):
        stray.unlink()
    for old in out_dir.glob("shard_*.npz"):
        index = int(old.stem.split("_")[1])
        if index >= shard_count or not shard_is_current(old, fp):
            old.unlink()
    jobs = [ShardJob(k, str(out_dir), fp, params) for k in range(shard_count)]
    todo = [job for job in jobs if not shard_path(out_dir, job.index).is_file()]
    bar = tqdm(total=shard_count, initial=shard_count - len(todo), desc=description, unit="shard", disable=not progress)
    if backend == "ray":
        for _ in _run_ray(make_shard, todo, workers):
            bar.update()
    else:
        if workers <= 1 or len(todo) <= 1:
            for job in todo:
                make_shard(job)
                bar.update()
        else:
            with ProcessPoolExecutor(max_workers=min(workers, len(todo))) as pool:
                for future in as_completed([pool.submit(make_shard, job) for job in todo]):
                    future.result()  # re-raises a worker's error
                    bar.update()
    bar.close()
    # Counts read back from every shard file, made now or earlier, so a resume writes the same manifest.
    shards = [{"file": shard_path(out_dir, k).name, **summarise_shard(shard_path(out_dir, k))} for k in range(shard_count)]
    manifest = {"params": params, "fingerprint": fp, "shards": shards, "totals": _totals(shards)}
    tmp = manifest_path.with_name(MANIFEST + ".tmp")
    tmp.write_text(json.dumps(manifest, indent=2, default=str) + "\n")
    os.replace(tmp, manifest_path)
    return {**manifest, "code_version": code_version(), "made_this_run": [job.index for job in todo]}


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
        print(f"note: {requested} {what} is not a multiple of {per_shard} per shard; "
              f"collecting {count} shards = {count * per_shard} {what}")
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


def _run_ray(make_shard: Callable[[ShardJob], dict[str, Any]], jobs: list[ShardJob], workers: int):
    import ray  # installed: run_shards checked
    if not ray.is_initialized():
        if os.environ.get("RAY_ADDRESS"):
            ray.init(log_to_driver=False)  # join the cluster RAY_ADDRESS names
        else:
            ray.init(num_cpus=workers if workers > 0 else None, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(make_shard)
    pending = {remote.remote(job): job.index for job in jobs}
    while pending:
        done, _ = ray.wait(list(pending), num_returns=1)
        for ref in done:
            yield pending.pop(ref), ray.get(ref)
