"""Short stable hashes of what made a piece of resumable work: settings, input files, code.

A stage keeps its unfinished work (shards, per-map results, training checkpoints) under
`checkpoints/`, outside its DVC outputs, together with the fingerprint of what made it. A
rerun takes that work up again only when the fingerprint is the same; otherwise it starts
afresh. The fingerprints never enter an output, so an output's bytes (and DVC's hash of
them) depend on the data alone, not on the commit of the code that made them.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Iterable, Sequence

PACKAGE = Path(__file__).resolve().parents[1]  # the pipeline package


def settings_digest(value: Any) -> str:
    """A hash of JSON-able settings (key order does not matter)."""
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()[:16]


def source_digest(sources: Sequence[str] | None = None) -> str:
    """A hash of the library's source: work made by other code is never taken up again.

    `sources` are the package-relative folders and files that determine the work (the whole
    package when None), so that editing an unrelated part does not throw work away.
    """
    digest = hashlib.sha256()
    paths: set[Path] = set()
    for source in [""] if sources is None else sources:
        path = PACKAGE / source
        paths.update(path.rglob("*.py") if path.is_dir() else [path])
    for path in sorted(paths):
        digest.update(path.relative_to(PACKAGE).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def files_digest(paths: Iterable[str | Path]) -> str:
    """A hash of files' contents and names; a folder counts every file under it (hidden ones not).

    A missing path hashes as missing, so that work made from an input that has since appeared
    or gone is not taken up again.
    """
    digest = hashlib.sha256()
    for root in sorted(Path(p) for p in paths):
        files = (
            sorted(f for f in root.rglob("*") if f.is_file() and not f.name.startswith("."))
            if root.is_dir()
            else [root]
        )
        for path in files:
            digest.update(path.as_posix().encode())
            if path.is_file():
                with path.open("rb") as handle:
                    for block in iter(lambda: handle.read(1 << 20), b""):
                        digest.update(block)
            else:
                digest.update(b"<missing>")
    return digest.hexdigest()[:16]
