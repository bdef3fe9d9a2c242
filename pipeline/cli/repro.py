"""`guide repro`: `dvc repro` that goes on after a killed run.

DVC records each running `dvc repro` in `.dvc/tmp/rwlock` by process id and command, and drops
an entry only when no process has that id. A run killed with its whole process group (an
out-of-memory killer, a lost terminal, a cluster's time limit) can leave entries whose id
belongs to another process by the time it runs again (a fresh container numbers its processes
from 1 again; a killed child may linger as a zombie), and DVC refuses to start. An entry is
stale when no live process has its id and its command; `guide repro` removes only those,
under DVC's own lock on the file, so a live run is never unlocked, then runs `dvc repro` with
the arguments given.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

import psutil
import typer

from pipeline.cli.options import fail

app = typer.Typer(rich_markup_mode=None)

RWLOCK = Path(".dvc/tmp/rwlock")


def holder_is_alive(entry: dict) -> bool:
    """Whether the process an rwlock entry names still runs the command it recorded."""
    try:
        process = psutil.Process(int(entry["pid"]))
        if process.status() == psutil.STATUS_ZOMBIE:
            return False
        return " ".join(process.cmdline()) == entry["cmd"]
    except (psutil.NoSuchProcess, psutil.AccessDenied, KeyError, ValueError, TypeError):
        return False  # gone, or another user's process: not the dvc that wrote the entry


def drop_stale_entries(lock: dict) -> list[str]:
    """Remove from `lock` (the rwlock's JSON) every entry whose holder is gone; the paths freed."""
    freed: list[str] = []
    for path, entry in list(lock.get("write", {}).items()):
        if not holder_is_alive(entry):
            del lock["write"][path]
            freed.append(path)
    for path, entries in list(lock.get("read", {}).items()):
        alive = [entry for entry in entries if holder_is_alive(entry)]
        if len(alive) < len(entries):
            freed.append(path)
        if alive:
            lock["read"][path] = alive
        else:
            del lock["read"][path]
    return freed


def clear_stale_locks(project: Path) -> list[str]:
    """Drop the stale entries of `project`'s `.dvc/tmp/rwlock` under DVC's lock on it; the paths freed."""
    from dvc.fs import localfs  # heavy: DVC, only when there is a lock file to edit
    from dvc.rwlock import _edit_rwlock

    if not (project / RWLOCK).is_file():
        return []
    with _edit_rwlock(str(project / RWLOCK.parent), localfs, False) as lock:
        return drop_stale_entries(lock)


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def repro(ctx: typer.Context) -> None:
    """`dvc repro [ARGS]` after clearing the locks of killed runs (run it in the project's root).

    A `dvc repro` killed anywhere, even with its whole process group, leaves entries in
    .dvc/tmp/rwlock that can stop the next one; this removes only entries whose process is gone
    (never a live run's) and runs `dvc repro` with ARGS, which resumes the killed stage.
    """
    project = Path.cwd()
    if not (project / ".dvc").is_dir():
        fail(f"{project} is not a DVC project (no .dvc folder): run guide repro in the project's root")
    if shutil.which("dvc") is None:
        fail("dvc is not installed: pip install -e .")
    try:
        freed = clear_stale_locks(project)
    except (ValueError, json.JSONDecodeError) as error:  # a corrupt lock file: DVC's own message says what to do
        fail(f"{RWLOCK}: {error}")
    if freed:
        typer.echo(f"guide repro: cleared the lock of a killed run on {len(freed)} path(s) in {RWLOCK}", err=True)
    sys.stdout.flush()
    sys.stderr.flush()
    # dvc takes this process's place (its id, its parent): whoever waits for `guide repro` reaps dvc,
    # and a kill of the job's process group leaves no orphan behind.
    os.execvpe("dvc", ["dvc", "repro", *ctx.args], {**os.environ, "DVC_NO_ANALYTICS": "1"})
