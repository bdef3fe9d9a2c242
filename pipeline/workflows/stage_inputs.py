"""What a stage reads from the stages before it: the maps `generate_mazes` wrote."""

from __future__ import annotations

from pathlib import Path

from pipeline.world.maps import list_maps


def generated_maps(folder: Path, what: str) -> list[Path]:
    """The maps in `folder`; SystemExit naming the stage to run when there are none (`what`: 'training mazes')."""
    maps = list_maps(folder)
    if not maps:
        raise SystemExit(f"error: {folder}: no {what}; run the generate_mazes stage first")
    return maps
