"""Results of a per-item map kept on disk, so that a killed stage takes them up again.

`KeptResults(folder, identity)` holds one file per finished item (`item_00012.pkl`) and the
fingerprint of `identity` (what determines every item: settings, input files, code; see
`pipeline.common.fingerprints`). Opening it with another identity empties the folder: those
results belong to other work. Each item appears atomically, so a kill leaves finished items
and nothing half-written. The files are this project's own pickles, written and read by the
same stage on the same machine.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
from pathlib import Path
from typing import Any

from pipeline.common.atomic import atomic_write_bytes, atomic_write_json
from pipeline.common.fingerprints import settings_digest

RECORD = "identity.json"


class KeptResults:
    """Finished items of one piece of work, by index, under `folder`."""

    def __init__(self, folder: str | Path, identity: dict[str, Any]) -> None:
        self.folder = Path(folder)
        self.fingerprint = settings_digest(identity)
        record = self.folder / RECORD
        same = False
        if record.is_file():
            try:
                same = json.loads(record.read_text()).get("fingerprint") == self.fingerprint
            except (OSError, ValueError):
                same = False
        if not same and self.folder.exists():
            shutil.rmtree(self.folder)
        if not same:
            self.folder.mkdir(parents=True, exist_ok=True)
            atomic_write_json(record, {"fingerprint": self.fingerprint, "identity": identity})

    def _path(self, index: int) -> Path:
        return self.folder / f"item_{index:05d}.pkl"

    def has(self, index: int) -> bool:
        return self._path(index).is_file()

    def get(self, index: int) -> Any:
        with self._path(index).open("rb") as handle:
            return pickle.load(handle)

    def put(self, index: int, result: Any) -> None:
        atomic_write_bytes(self._path(index), pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))

    def count(self) -> int:
        return sum(1 for name in os.listdir(self.folder) if name.startswith("item_") and name.endswith(".pkl"))
