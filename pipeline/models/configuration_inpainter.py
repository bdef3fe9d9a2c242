"""Configuration of the node-image inpainter: LaMa's FFC ResNet generator at any size.

The default is a small generator (about 0.6 M parameters) that trains on a laptop CPU in
minutes and predicts a 48 x 48 node image in a few milliseconds. `InpainterConfig.big_lama()`
gives the layout of the official Big-LaMa generator (configs/training/big-lama.yaml of
advimman/lama: ngf 64, 3 downsamplings, 18 FFC residual blocks at 512 channels, global
ratio 0.75 in the blocks and 0 in the first convolution and the downsamplings, no LFU,
sigmoid output), so its published weights can initialise training.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from pipeline.common.params import dataclass_from_dict

# How a node image (255 free, 0 obstacle, 128 unknown) becomes the network's input channels.
#   signed: [+1 free / -1 obstacle / 0 unknown, unknown mask]                   -> 2 channels
#   lama:   [masked image (1 free, 0 obstacle or unknown), unknown mask]        -> 2 channels
#           (LaMa's own input: image * (1 - mask) and the mask; with 4 channels
#           the grey image is repeated as RGB, exactly the official input)      -> 2 or 4 channels
#   onehot: [free, obstacle, unknown]                                           -> 3 channels
INPUT_ENCODINGS = {"signed": (2,), "lama": (2, 4), "onehot": (3,)}


@dataclass
class InpainterConfig:
    """Layout of an FFC ResNet generator (LaMa's `ffc_resnet`), with LaMa's argument names."""

    in_channels: int = 2
    out_channels: int = 1
    ngf: int = 16  # width of the first convolution; doubled by every downsampling
    n_downsampling: int = 3  # stride-2 convolutions (image side must be a multiple of 2**n)
    n_blocks: int = 3  # FFC residual blocks at the bottleneck
    max_features: int = 1024  # channel cap (LaMa's default; Big-LaMa never reaches it)
    init_ratio_g: float = 0.0  # global share of the first 7x7 convolution (in and out)
    downsample_ratio_g: float = 0.0  # global share inside the downsamplings
    ratio_gin: float = 0.75  # global share of the residual blocks' input channels
    ratio_gout: float = 0.75  # ... and of their output channels
    enable_lfu: bool = False  # LaMa's local Fourier unit (off in Big-LaMa)
    init_kernel_size: int = 7
    downsample_kernel_size: int = 3
    block_kernel_size: int = 3
    upsample_kernel_size: int = 3
    out_kernel_size: int = 7
    padding_type: str = "reflect"
    fft_norm: str = "ortho"
    input_encoding: str = "signed"

    def __post_init__(self) -> None:
        if self.input_encoding not in INPUT_ENCODINGS:
            raise ValueError(f"input_encoding {self.input_encoding!r}: use one of {sorted(INPUT_ENCODINGS)}")
        if self.in_channels not in INPUT_ENCODINGS[self.input_encoding]:
            raise ValueError(
                f"input_encoding {self.input_encoding!r} makes {INPUT_ENCODINGS[self.input_encoding]} input "
                f"channels, not in_channels={self.in_channels}"
            )
        if self.out_channels < 1 or self.ngf < 1 or self.n_downsampling < 0 or self.n_blocks < 0:
            raise ValueError("out_channels and ngf must be >= 1, n_downsampling and n_blocks >= 0")
        for name in ("init_ratio_g", "downsample_ratio_g", "ratio_gin", "ratio_gout"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1]")
        for name in ("init_kernel_size", "downsample_kernel_size", "block_kernel_size", "upsample_kernel_size", "out_kernel_size"):
            if getattr(self, name) % 2 != 1:
                raise ValueError(f"{name} must be odd")
        if self.ratio_gin != self.ratio_gout:
            raise ValueError("ratio_gin and ratio_gout must be equal (the residual blocks add input and output)")
        if self.padding_type not in ("reflect", "zeros", "replicate", "circular"):
            raise ValueError(f"padding_type {self.padding_type!r}")

    @property
    def size_multiple(self) -> int:
        """Image sides must be multiples of this (2 ** n_downsampling)."""
        return 2**self.n_downsampling

    @property
    def bottleneck_channels(self) -> int:
        return min(self.max_features, self.ngf * 2**self.n_downsampling)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "InpainterConfig":
        """Build from a dict (params.yaml, an exported model); unknown keys are an error."""
        values = dict(values or {})
        if values.pop("big_lama", False):
            return cls.big_lama(**values)
        return dataclass_from_dict(cls, values, "inpainter config keys")

    @classmethod
    def big_lama(cls, in_channels: int = 2, out_channels: int = 1, input_encoding: str = "lama", **overrides: Any) -> "InpainterConfig":
        """The official Big-LaMa generator layout (51 M parameters with 4 in / 3 out channels).

        The official model takes 4 channels (masked RGB + mask) and returns 3 (RGB); ours
        defaults to 2 in (masked grey node image + mask) and 1 out (free-node probability);
        `load_big_lama_generator` adapts the first and last convolutions.
        """
        values: dict[str, Any] = dict(
            in_channels=in_channels,
            out_channels=out_channels,
            ngf=64,
            n_downsampling=3,
            n_blocks=18,
            max_features=1024,
            init_ratio_g=0.0,
            downsample_ratio_g=0.0,
            ratio_gin=0.75,
            ratio_gout=0.75,
            enable_lfu=False,
            init_kernel_size=7,
            downsample_kernel_size=3,
            block_kernel_size=3,
            upsample_kernel_size=3,
            out_kernel_size=7,
            padding_type="reflect",
            fft_norm="ortho",
            input_encoding=input_encoding,
        )
        values.update(overrides)
        return cls(**values)
