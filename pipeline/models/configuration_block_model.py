"""Configuration of the block model: a small dilated CNN that completes the maze's block grid.

The defaults (about 170 k parameters) see about 35 blocks (175 m) across through their
dilations, enough for a 100 m maze in one pass; 4 epochs on 10,000 snapshots take about
3 minutes on 2 CPU cores, and one prediction on a 20 x 20 grid under a millisecond.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from pipeline.common.params import dataclass_from_dict

INPUT_CHANNELS = 4  # known-free share, known-wall share, unknown share, outer ring


@dataclass(frozen=True)
class BlockModelConfig:
    """Widths of the block model and the block size it was trained at (a prior of the maps)."""

    width: int = 48
    dilations: tuple[int, ...] = (1, 2, 4, 8, 1, 2, 4, 1)
    groups: int = 8  # GroupNorm groups; must divide width
    block_m: float = 5.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "dilations", tuple(int(d) for d in self.dilations))
        if isinstance(self.width, bool) or not isinstance(self.width, int) or self.width < 1:
            raise ValueError(f"BlockModelConfig.width must be a whole number >= 1, got {self.width!r}")
        if isinstance(self.groups, bool) or not isinstance(self.groups, int) or self.groups < 1 or self.width % self.groups:
            raise ValueError(f"BlockModelConfig.groups must divide width {self.width}, got {self.groups!r}")
        if not self.dilations or min(self.dilations) < 1:
            raise ValueError(f"BlockModelConfig.dilations must be whole numbers >= 1, got {self.dilations!r}")
        if not self.block_m > 0:
            raise ValueError(f"BlockModelConfig.block_m must be positive, got {self.block_m!r}")

    def to_dict(self) -> dict[str, Any]:
        values = asdict(self)
        values["dilations"] = list(self.dilations)
        return values

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> "BlockModelConfig":
        return dataclass_from_dict(cls, values, "block model config key(s)")
