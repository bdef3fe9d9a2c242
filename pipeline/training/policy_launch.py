"""`train_planner` as a script of its own, for callers that must not be run again by DDP.

Lightning starts the other processes of a multi-device run by running the caller's script again,
one process per device. A stage that only trains (`train_planner`) is fine with that. A stage that
collects its data before each training (`distil_policy`'s DAgger rounds) is not: every process
would collect the data again. Such a caller runs the training through `train_in_subprocess`. The
child process only trains, and it is this script that Lightning runs again for each device.

    python -m pipeline.training.policy_launch SETTINGS_JSON

SETTINGS_JSON holds `train_planner`'s keyword arguments.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from pipeline.training.policy import train_planner

MODULE = "pipeline.training.policy_launch"


def _plain(value: Any) -> Any:
    return str(value) if isinstance(value, Path) else value


def train_in_subprocess(**arguments: Any) -> Path:
    """`train_planner(**arguments)` in a child process that starts its own DDP processes. Returns
    the export's path, which rank zero writes. RuntimeError, with the end of the child's output,
    when the training fails."""
    settings = json.dumps({key: _plain(value) for key, value in arguments.items()})
    done = subprocess.run(
        [sys.executable, "-m", MODULE, settings], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    if done.returncode != 0:
        raise RuntimeError(f"the policy training failed (exit {done.returncode}):\n{done.stdout[-3000:]}")
    export = Path(arguments["out_dir"]) / "policy.pt"
    if not export.is_file():
        raise RuntimeError(f"the policy training ended without writing {export}:\n{done.stdout[-3000:]}")
    return export


def main(argv: list[str]) -> None:
    if len(argv) != 1:
        raise SystemExit(f"usage: python -m {MODULE} SETTINGS_JSON (train_planner's keyword arguments)")
    train_planner(**json.loads(argv[0]))


if __name__ == "__main__":
    main(sys.argv[1:])
