"""Configuration of the block model: a small dilated CNN that completes the maze's block grid.

The defaults (about 170 k parameters) see about 35 blocks (175 m) across through their
dilations, enough for a 100 m maze in one pass; 4 epochs on 10,000 snapshots take about
3 minutes on 2 CPU cores, and one prediction on a 20 x 20 grid under a millisecond.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Annotated, Any

from pipeline.common.config import config_dataclass, list_of, positive, validate, whole

INPUT_CHANNELS = 4  # known-free share, known-wall share, unknown share, outer ring


@config_dataclass
class BlockModelConfig:
    """Widths of the block model and the block size it was trained at (a prior of the maps)."""

    width: Annotated[int, whole(1)] = 48
    dilations: Annotated[list[int], list_of(whole(1))] = (  # type: ignore[assignment]  # a tuple default, as the field is once made
        1,
        2,
        4,
        8,
        1,
        2,
        4,
        1,
    )  # a tuple once made: YAML and JSON give lists
    groups: Annotated[int, whole(1)] = 8  # GroupNorm groups; must divide width
    block_m: Annotated[float, positive("metres")] = 5.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "dilations", tuple(self.dilations))  # hashable and comparable
        if self.width % self.groups:
            raise ValueError(f"groups ({self.groups}) must divide width ({self.width})")

    def to_dict(self) -> dict[str, Any]:
        values = asdict(self)
        values["dilations"] = list(self.dilations)
        return values

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None, root: str = "model") -> "BlockModelConfig":
        """Build from a dict (params.yaml's `train_block_model.model`, a saved model); a refused
        value or an unknown key is a one-line ValueError naming it as `root.key`."""
        return validate(cls, values, root)
