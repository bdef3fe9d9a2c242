"""Configuration of the node-image inpainter: LaMa's FFC ResNet generator at any size.

The default is a small generator (about 0.6 M parameters) that trains on a laptop CPU in
minutes and predicts a 48 x 48 node image in a few milliseconds. `InpainterConfig.big_lama()`
gives the layout of the official Big-LaMa generator (configs/training/big-lama.yaml of
advimman/lama: ngf 64, 3 downsamplings, 18 FFC residual blocks at 512 channels, global
ratio 0.75 in the blocks and 0 in the first convolution and the downsamplings, no LFU,
sigmoid output), so its published weights can initialise training.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict
from typing import Annotated, Any

from pydantic import model_validator

from pipeline.common.config import check_value, config_dataclass, flag, fraction, satisfies, text, validate, whole

# How a node image (255 free, 0 obstacle, 128 unknown) becomes the network's input channels.
#   signed: [+1 free / -1 obstacle / 0 unknown, unknown mask]                   -> 2 channels
#   lama:   [masked image (1 free, 0 obstacle or unknown), unknown mask]        -> 2 channels
#           (LaMa's own input: image * (1 - mask) and the mask; with 4 channels
#           the grey image is repeated as RGB, exactly the official input)      -> 2 or 4 channels
#   onehot: [free, obstacle, unknown]                                           -> 3 channels
INPUT_ENCODINGS = {"signed": (2,), "lama": (2, 4), "onehot": (3,)}
PADDING_TYPES = ("reflect", "zeros", "replicate", "circular")  # torch's Conv2d padding modes
FFT_NORMS = ("backward", "forward", "ortho")  # torch.fft's normalisations


def _odd(size: int) -> None:
    if size % 2 != 1:
        raise ValueError("a convolution pads half of it on each side")


KERNEL = satisfies(_odd, "an odd kernel size", kind=whole(1))


@config_dataclass
class InpainterConfig:
    """Layout of an FFC ResNet generator (LaMa's `ffc_resnet`), with LaMa's argument names."""

    in_channels: Annotated[int, whole(1)] = 2
    out_channels: Annotated[int, whole(1)] = 1
    ngf: Annotated[int, whole(1)] = 16  # width of the first convolution; doubled by every downsampling
    n_downsampling: Annotated[int, whole(0)] = 3  # stride-2 convolutions (image side must be a multiple of 2**n)
    n_blocks: Annotated[int, whole(0)] = 3  # FFC residual blocks at the bottleneck
    max_features: Annotated[int, whole(1)] = 1024  # channel cap (LaMa's default; Big-LaMa never reaches it)
    init_ratio_g: Annotated[float, fraction()] = 0.0  # global share of the first 7x7 convolution (in and out)
    downsample_ratio_g: Annotated[float, fraction()] = 0.0  # global share inside the downsamplings
    ratio_gin: Annotated[float, fraction()] = 0.75  # global share of the residual blocks' input channels
    ratio_gout: Annotated[float, fraction()] = 0.75  # ... and of their output channels
    enable_lfu: Annotated[bool, flag()] = False  # LaMa's local Fourier unit (off in Big-LaMa)
    init_kernel_size: Annotated[int, KERNEL] = 7
    downsample_kernel_size: Annotated[int, KERNEL] = 3
    block_kernel_size: Annotated[int, KERNEL] = 3
    upsample_kernel_size: Annotated[int, KERNEL] = 3
    out_kernel_size: Annotated[int, KERNEL] = 7
    padding_type: Annotated[str, text(PADDING_TYPES)] = "reflect"
    fft_norm: Annotated[str, text(FFT_NORMS)] = "ortho"
    input_encoding: Annotated[str, text(tuple(INPUT_ENCODINGS))] = "signed"

    @model_validator(mode="before")
    @classmethod
    def _big_lama_mapping(cls, values: Any) -> Any:
        """A mapping (a `model:` in a stage's settings) may say `big_lama: true` (see `from_dict`)."""
        return cls.with_big_lama(values, "big_lama") if isinstance(values, Mapping) else values

    def __post_init__(self) -> None:
        if self.in_channels not in INPUT_ENCODINGS[self.input_encoding]:
            raise ValueError(
                f"input_encoding {self.input_encoding!r} makes {INPUT_ENCODINGS[self.input_encoding]} input "
                f"channels, not in_channels={self.in_channels}"
            )
        if self.ratio_gin != self.ratio_gout:
            raise ValueError("ratio_gin and ratio_gout must be equal (the residual blocks add input and output)")

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
    def from_dict(cls, values: dict[str, Any] | None, root: str = "model") -> "InpainterConfig":
        """Build from a dict (params.yaml, an exported model); `big_lama: true` starts from the
        Big-LaMa layout, which the other keys override. A refused value or an unknown key is a
        one-line ValueError naming it as `root.key`."""
        return validate(cls, cls.with_big_lama(values or {}, f"{root}.big_lama"), root)

    @classmethod
    def with_big_lama(cls, values: Mapping[str, Any], key: str) -> dict[str, Any]:
        """`values` without their `big_lama` flag: under the Big-LaMa layout when it is true. A flag
        that is not true or false is a ValueError naming it as `key`."""
        values = dict(values)
        if check_value(flag(), values.pop("big_lama", False), key):
            values = {**cls.big_lama_layout(), **values}
        return values

    @staticmethod
    def big_lama_layout(in_channels: int = 2, out_channels: int = 1, input_encoding: str = "lama") -> dict[str, Any]:
        """The official Big-LaMa generator layout as config values (see `big_lama`)."""
        return dict(
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

    @classmethod
    def big_lama(
        cls, in_channels: int = 2, out_channels: int = 1, input_encoding: str = "lama", **overrides: Any
    ) -> "InpainterConfig":
        """The official Big-LaMa generator layout (51 M parameters with 4 in / 3 out channels).

        The official model takes 4 channels (masked RGB + mask) and returns 3 (RGB); ours
        defaults to 2 in (masked grey node image + mask) and 1 out (free-node probability);
        `load_big_lama_generator` adapts the first and last convolutions.
        """
        return cls(**{**cls.big_lama_layout(in_channels, out_channels, input_encoding), **overrides})
