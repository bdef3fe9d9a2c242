"""Where the pipeline's stages read and write: `pipeline/paths.yaml`, which dvc.yaml reads too, so
that each path is written down once. Paths are relative to the project folder (where `dvc repro`
runs)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import yaml

PATHS_FILE = Path(__file__).resolve().parents[1] / "paths.yaml"


def _group(values: dict[str, str]) -> SimpleNamespace:
    return SimpleNamespace(**{name: Path(path) for name, path in values.items()})


_PATHS = yaml.safe_load(PATHS_FILE.read_text(encoding="utf-8"))
DATA = _group(_PATHS["data"])
MODELS = _group(_PATHS["models"])
REPORTS = _group(_PATHS["reports"])
CHECKPOINTS = _group(_PATHS["checkpoints"])  # outside every stage output: DVC deletes those before a rerun
POLICIES = {variant: _group(paths) for variant, paths in _PATHS["policies"].items()}  # "guide", "dare"
