"""A plain training loop's state after its last finished epoch, kept so that a killed run goes on.

`TrainingCheckpoint(folder, fingerprint)` keeps `folder/last.pt`: the weights, the optimiser
and schedule, the random generators' states, the history, and the fingerprint of the settings
and data it was made with (`pipeline.common.fingerprints`). `load()` gives it back only when
the fingerprint is the same, and says in one line whether the run resumes or starts afresh.
The file is replaced atomically after each epoch, so a kill leaves the previous epoch's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from pipeline.common.atomic import atomic_file

LAST = "last.pt"


class TrainingCheckpoint:
    def __init__(self, folder: str | Path, fingerprint: str, what: str = "training") -> None:
        self.path = Path(folder) / LAST
        self.fingerprint = fingerprint
        self.what = what

    def load(self) -> dict[str, Any] | None:
        """The state saved by an earlier run of the same settings and data, or None (a fresh start)."""
        if not self.path.is_file():
            return None
        try:
            state = torch.load(self.path, map_location="cpu", weights_only=True)
        except Exception as error:  # noqa: BLE001 - any unreadable file means: start afresh
            print(f"{self.what}: {self.path} is unreadable ({type(error).__name__}): training afresh")
            return None
        if not isinstance(state, dict) or state.get("fingerprint") != self.fingerprint:
            print(f"{self.what}: {self.path} was made with other settings or data: training afresh")
            return None
        print(f"{self.what}: resuming from {self.path} after epoch {state['epoch']}")
        return state

    def save(self, state: dict[str, Any]) -> None:
        with atomic_file(self.path) as tmp:
            torch.save({**state, "fingerprint": self.fingerprint}, tmp)
