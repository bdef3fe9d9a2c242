"""The trained models planners run, loaded once per process.

A benchmark worker builds a planner per episode; reading and tracing the inpainter and the
policy each time would cost more than many episodes' decisions. This cache is the one piece
of process-wide state the planners share. It is keyed by (what was built, resolved path): a
file replaced under the same path is not read again by a running process (training runs in
another one).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Callable, TypeVar

Model = TypeVar("Model")

_CACHE: dict[tuple[str, str], object] = {}
_LOCK = threading.Lock()


def load_once(kind: str, path: str | Path, loader: Callable[[Path], Model]) -> Model:
    """`loader(path)`, called on the first request for (`kind`, `path`) in this process only.

    Loading sets torch to one CPU thread for the whole process: a second OpenMP thread made a
    small prediction many times slower when two benchmark workers shared the cores, and gains
    nothing for these small models when the cores are free.
    """
    key = (kind, str(Path(path).resolve()))
    with _LOCK:
        if key not in _CACHE:
            import torch

            torch.set_num_threads(1)
            _CACHE[key] = loader(Path(path))
    return _CACHE[key]  # type: ignore[return-value]
