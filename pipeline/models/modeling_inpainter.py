"""LaMa's FFC ResNet generator, written for node images, with the official state-dict layout.

Architecture (Suvorov et al., "Resolution-robust Large Mask Inpainting with Fourier
Convolutions", 2022): reflect-padded 7x7 convolution, stride-2 downsamplings, a stack of
fast-Fourier-convolution (FFC) residual blocks, transposed-convolution upsamplings, a 7x7
convolution and a sigmoid. An FFC splits its channels into a local part (ordinary
convolutions) and a global part whose global-to-global path is a spectral transform:
1x1 conv -> FourierUnit (rfft2, 1x1 conv + BN + ReLU on the stacked real and imaginary
parts, irfft2) -> 1x1 conv, so every output pixel sees the whole image in one layer.

Module and parameter names follow the official generator exactly (`model.1.ffc.convl2l`,
`model.5.conv1.ffc.convg2g.fu.conv_layer`, `model.24` for the first transposed
convolution, ...), so `load_big_lama_generator` can load the published Big-LaMa weights
into `InpainterConfig.big_lama()`; absent branches are `None` (no parameters), where the
official code puts an `nn.Identity`.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Literal, Optional, cast

import numpy as np
import torch
import torch.nn as nn

from pipeline.models.configuration_inpainter import InpainterConfig
from pipeline.models.exports import INPAINTER_FORMAT, export_kind, read_weights_file, write_weights_file

PIXEL_FREE_MIN = 192  # node image values >= this are free nodes (255)
PIXEL_OBSTACLE_MAX = 63  # values <= this are obstacle nodes (0); anything between is unknown (128)

Pair = tuple[Optional[torch.Tensor], Optional[torch.Tensor]]  # (local, global) feature maps


# ----------------------------------------------------------------------------- FFC parts
class FourierUnit(nn.Module):
    """rfft2 -> 1x1 conv + BN + ReLU on [real, imag] channel pairs -> irfft2 (a global filter)."""

    def __init__(self, in_channels: int, out_channels: int, groups: int = 1, fft_norm: str = "ortho") -> None:
        super().__init__()
        self.conv_layer = nn.Conv2d(in_channels * 2, out_channels * 2, kernel_size=1, groups=groups, bias=False)
        self.bn = nn.BatchNorm2d(out_channels * 2)
        self.relu = nn.ReLU()
        self.fft_norm = fft_norm

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        batch, _, height, width = x.shape
        dtype = x.dtype
        spectrum = torch.fft.rfft2(x.float(), norm=self.fft_norm)  # (B, C, H, W/2+1) complex
        # Channel order [c0.re, c0.im, c1.re, c1.im, ...], as the official unit stacks them.
        stacked = torch.view_as_real(spectrum).permute(0, 1, 4, 2, 3).reshape(batch, -1, height, spectrum.shape[-1])
        stacked = self.relu(self.bn(self.conv_layer(stacked.to(dtype))))
        pairs = stacked.float().reshape(batch, -1, 2, height, spectrum.shape[-1]).permute(0, 1, 3, 4, 2).contiguous()
        out = torch.fft.irfft2(torch.view_as_complex(pairs), s=(height, width), norm=self.fft_norm)
        return out.to(dtype)


class SpectralTransform(nn.Module):
    """The global-to-global path: 1x1 conv (halving) -> FourierUnit (+ optional LFU) -> 1x1 conv."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        stride: int = 1,
        groups: int = 1,
        enable_lfu: bool = False,
        fft_norm: str = "ortho",
    ) -> None:
        super().__init__()
        self.enable_lfu = enable_lfu
        self.downsample = nn.AvgPool2d(kernel_size=2, stride=2) if stride == 2 else nn.Identity()
        hidden = out_channels // 2
        self.conv1 = nn.Sequential(
            nn.Conv2d(in_channels, hidden, kernel_size=1, groups=groups, bias=False), nn.BatchNorm2d(hidden), nn.ReLU()
        )
        self.fu = FourierUnit(hidden, hidden, groups, fft_norm=fft_norm)
        self.lfu = FourierUnit(hidden, hidden, groups, fft_norm=fft_norm) if enable_lfu else None
        self.conv2 = nn.Conv2d(hidden, out_channels, kernel_size=1, groups=groups, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.conv1(self.downsample(x))
        out = x + self.fu(x)
        if self.lfu is not None:
            # Local Fourier unit: the first quarter of the channels, cut into 2 x 2 spatial
            # tiles stacked as channels, filtered in the spectrum, tiled back.
            _, channels, height, width = x.shape
            if height % 2 or width % 2:
                raise ValueError(f"the local Fourier unit needs even feature maps, got {height}x{width}")
            quarter = x[:, : channels // 4]
            tiles = torch.cat(torch.split(quarter, height // 2, dim=-2), dim=1)
            tiles = torch.cat(torch.split(tiles, width // 2, dim=-1), dim=1)
            out = out + self.lfu(tiles).repeat(1, 1, 2, 2)
        return self.conv2(out)


class FFC(nn.Module):
    """Fast Fourier convolution: local/global channel split with four cross paths."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        kernel_size: int,
        ratio_gin: float,
        ratio_gout: float,
        stride: int = 1,
        padding: int = 0,
        dilation: int = 1,
        groups: int = 1,
        bias: bool = False,
        enable_lfu: bool = False,
        padding_type: str = "reflect",
        fft_norm: str = "ortho",
    ) -> None:
        super().__init__()
        if stride not in (1, 2):
            raise ValueError("FFC stride must be 1 or 2")
        in_cg = int(in_channels * ratio_gin)
        in_cl = in_channels - in_cg
        out_cg = int(out_channels * ratio_gout)
        out_cl = out_channels - out_cg
        self.ratio_gin, self.ratio_gout = ratio_gin, ratio_gout
        self.global_in_num = in_cg

        def conv(cin: int, cout: int) -> Optional[nn.Conv2d]:
            if cin == 0 or cout == 0:
                return None
            return nn.Conv2d(
                cin,
                cout,
                kernel_size,
                stride,
                padding,
                dilation,
                groups,
                bias,
                padding_mode=cast('Literal["zeros", "reflect", "replicate", "circular"]', padding_type),
            )

        self.convl2l = conv(in_cl, out_cl)
        self.convl2g = conv(in_cl, out_cg)
        self.convg2l = conv(in_cg, out_cl)
        self.convg2g = (
            SpectralTransform(in_cg, out_cg, stride, 1 if groups == 1 else groups // 2, enable_lfu, fft_norm)
            if in_cg and out_cg
            else None
        )

    def forward(self, x: torch.Tensor | Pair) -> Pair:
        x_l, x_g = x if isinstance(x, tuple) else (x, None)
        out_l = _add(_apply(self.convl2l, x_l), _apply(self.convg2l, x_g))
        out_g = _add(_apply(self.convl2g, x_l), _apply(self.convg2g, x_g))
        return out_l, out_g


def _apply(module: Optional[nn.Module], x: Optional[torch.Tensor]) -> Optional[torch.Tensor]:
    return None if module is None or x is None else module(x)


def _add(a: Optional[torch.Tensor], b: Optional[torch.Tensor]) -> Optional[torch.Tensor]:
    if a is None:
        return b
    return a if b is None else a + b


class FFC_BN_ACT(nn.Module):  # noqa: N801 - the official class name
    """FFC followed by BatchNorm and an activation on each of the local and global parts."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        kernel_size: int,
        ratio_gin: float,
        ratio_gout: float,
        stride: int = 1,
        padding: int = 0,
        dilation: int = 1,
        enable_lfu: bool = False,
        padding_type: str = "reflect",
        fft_norm: str = "ortho",
        activation: bool = True,
    ) -> None:
        super().__init__()
        self.ffc = FFC(
            in_channels,
            out_channels,
            kernel_size,
            ratio_gin,
            ratio_gout,
            stride,
            padding,
            dilation,
            enable_lfu=enable_lfu,
            padding_type=padding_type,
            fft_norm=fft_norm,
        )
        out_cg = int(out_channels * ratio_gout)
        out_cl = out_channels - out_cg
        self.bn_l = nn.BatchNorm2d(out_cl) if out_cl else None
        self.bn_g = nn.BatchNorm2d(out_cg) if out_cg else None
        self.act_l = nn.ReLU() if activation and out_cl else None
        self.act_g = nn.ReLU() if activation and out_cg else None

    def forward(self, x: torch.Tensor | Pair) -> Pair:
        x_l, x_g = self.ffc(x)
        return self._norm_act(x_l, self.bn_l, self.act_l), self._norm_act(x_g, self.bn_g, self.act_g)

    @staticmethod
    def _norm_act(
        x: Optional[torch.Tensor], norm: Optional[nn.Module], act: Optional[nn.Module]
    ) -> Optional[torch.Tensor]:
        if x is None:
            return None
        x = norm(x) if norm is not None else x
        return act(x) if act is not None else x


class FFCResnetBlock(nn.Module):
    """Two FFC_BN_ACT (3x3) with a residual connection on both the local and global parts."""

    def __init__(
        self,
        dim: int,
        ratio_gin: float,
        ratio_gout: float,
        kernel_size: int = 3,
        dilation: int = 1,
        enable_lfu: bool = False,
        padding_type: str = "reflect",
        fft_norm: str = "ortho",
    ) -> None:
        super().__init__()
        padding = dilation * (kernel_size // 2)
        kwargs: dict[str, Any] = dict(
            kernel_size=kernel_size,
            ratio_gin=ratio_gin,
            ratio_gout=ratio_gout,
            padding=padding,
            dilation=dilation,
            enable_lfu=enable_lfu,
            padding_type=padding_type,
            fft_norm=fft_norm,
        )
        self.conv1 = FFC_BN_ACT(dim, dim, **kwargs)
        self.conv2 = FFC_BN_ACT(dim, dim, **kwargs)

    def forward(self, x: torch.Tensor | Pair) -> Pair:
        x_l, x_g = x if isinstance(x, tuple) else (x, None)
        y_l, y_g = self.conv2(self.conv1((x_l, x_g)))
        return _add(x_l, y_l), _add(x_g, y_g)


class ConcatTupleLayer(nn.Module):
    """(local, global) -> one tensor, local channels first."""

    def forward(self, x: torch.Tensor | Pair) -> torch.Tensor:
        if not isinstance(x, tuple):
            return x
        parts = [t for t in x if t is not None]
        return parts[0] if len(parts) == 1 else torch.cat(parts, dim=1)


# ----------------------------------------------------------------------------- generator
def encode_node_image(node_image: torch.Tensor, encoding: str, in_channels: int) -> torch.Tensor:
    """Node image (B, 1, H, W) or (B, H, W), values 255 free / 0 obstacle / 128 unknown -> input channels."""
    if node_image.dim() == 3:
        node_image = node_image.unsqueeze(1)
    if node_image.dim() != 4 or node_image.shape[1] != 1:
        raise ValueError(f"expected a node image batch (B, 1, H, W), got shape {tuple(node_image.shape)}")
    free = (node_image >= PIXEL_FREE_MIN).float()
    obstacle = (node_image <= PIXEL_OBSTACLE_MAX).float()
    unknown = 1.0 - free - obstacle
    if encoding == "signed":
        channels = [free - obstacle, unknown]
    elif encoding == "lama":
        channels = [free] * (in_channels - 1) + [unknown]  # masked grey image (as RGB if 4 channels) + mask
    elif encoding == "onehot":
        channels = [free, obstacle, unknown]
    else:
        raise ValueError(f"unknown input encoding {encoding!r}")
    return torch.cat(channels, dim=1)


class InpainterModel(nn.Module):
    """FFC ResNet generator: node image (B, 1, S, S) -> free-node probability (B, out, S, S).

    `self.model` is an `nn.Sequential` with the official generator's indices: 0 pad,
    1 first conv, 2.. downsamplings, then the residual blocks, a ConcatTupleLayer, three
    (ConvTranspose2d, BatchNorm2d, ReLU) upsamplings, pad, the last conv and the sigmoid.
    """

    def __init__(self, config: InpainterConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or InpainterConfig()
        c = config
        maxf = c.max_features

        def width(mult: float) -> int:
            return min(maxf, int(c.ngf * mult))

        # Global share of each stage's output: the first conv, then every downsampling; the
        # last downsampling hands the blocks their input ratio (as the official generator).
        init_gout = c.init_ratio_g if c.n_downsampling > 0 else c.ratio_gin
        layers: list[nn.Module] = [
            nn.ReflectionPad2d(c.init_kernel_size // 2),
            FFC_BN_ACT(
                c.in_channels,
                c.ngf,
                c.init_kernel_size,
                c.init_ratio_g,
                init_gout,
                padding=0,
                enable_lfu=c.enable_lfu,
                padding_type=c.padding_type,
                fft_norm=c.fft_norm,
            ),
        ]
        ratio_in = init_gout
        for i in range(c.n_downsampling):
            ratio_out = c.ratio_gin if i == c.n_downsampling - 1 else c.downsample_ratio_g
            layers.append(
                FFC_BN_ACT(
                    width(2**i),
                    width(2 ** (i + 1)),
                    c.downsample_kernel_size,
                    ratio_in,
                    ratio_out,
                    stride=2,
                    padding=c.downsample_kernel_size // 2,
                    enable_lfu=c.enable_lfu,
                    padding_type=c.padding_type,
                    fft_norm=c.fft_norm,
                )
            )
            ratio_in = ratio_out
        for _ in range(c.n_blocks):
            layers.append(
                FFCResnetBlock(
                    c.bottleneck_channels,
                    c.ratio_gin,
                    c.ratio_gout,
                    c.block_kernel_size,
                    enable_lfu=c.enable_lfu,
                    padding_type=c.padding_type,
                    fft_norm=c.fft_norm,
                )
            )
        layers.append(ConcatTupleLayer())
        for i in range(c.n_downsampling):
            mult = 2 ** (c.n_downsampling - i)
            layers += [
                nn.ConvTranspose2d(
                    width(mult),
                    width(mult / 2),
                    c.upsample_kernel_size,
                    stride=2,
                    padding=c.upsample_kernel_size // 2,
                    output_padding=1,
                ),
                nn.BatchNorm2d(width(mult / 2)),
                nn.ReLU(),
            ]
        layers += [
            nn.ReflectionPad2d(c.out_kernel_size // 2),
            nn.Conv2d(width(1), c.out_channels, c.out_kernel_size),
            nn.Sigmoid(),
        ]
        self.model = nn.Sequential(*layers)

    # -- forward passes -------------------------------------------------------------
    def encode(self, node_image: torch.Tensor) -> torch.Tensor:
        """The network input for a node image batch (see `encode_node_image`)."""
        param = next(self.parameters())
        x = encode_node_image(node_image.to(param.device), self.config.input_encoding, self.config.in_channels)
        return x.to(param.dtype)

    def check_size(self, height: int, width: int) -> None:
        multiple = self.config.size_multiple
        if height % multiple or width % multiple:
            raise ValueError(
                f"node image is {height}x{width}: both sides must be multiples of {multiple} "
                f"(2 ** n_downsampling = 2 ** {self.config.n_downsampling}); centre-pad it with unknown pixels"
            )

    def forward_encoded_logits(self, x: torch.Tensor) -> torch.Tensor:
        """Logits (before the sigmoid) for already encoded input channels (B, in_channels, H, W)."""
        self.check_size(x.shape[-2], x.shape[-1])
        last = len(self.model) - 1
        for index, layer in enumerate(self.model):
            if index == last:  # the sigmoid
                break
            x = layer(x)
        return x

    def forward_logits(self, node_image: torch.Tensor) -> torch.Tensor:
        """Logits of the free-node probability for a node image batch."""
        return self.forward_encoded_logits(self.encode(node_image))

    def forward(self, node_image: torch.Tensor) -> torch.Tensor:
        """Free-node probability (B, out_channels, H, W) for a node image batch (B, 1, H, W)."""
        return torch.sigmoid(self.forward_logits(node_image))

    @torch.inference_mode()
    def predict(self, observed: np.ndarray) -> np.ndarray:
        """Free-node probabilities for one (H, W) or a batch (B, H, W) of uint8 node images.

        Call `.eval()` first (the loader does): in training mode BatchNorm uses batch statistics.
        """
        array = np.asarray(observed)
        single = array.ndim == 2
        batch = torch.from_numpy(np.ascontiguousarray(array[None] if single else array))
        probs = self.forward(batch.unsqueeze(1))[:, 0].float().cpu().numpy()
        return probs[0] if single else probs

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())


# ----------------------------------------------------------------------------- official weights


def read_checkpoint(path) -> dict:
    """Read a .ckpt/.pth file; falls back to full unpickling (LaMa's checkpoints hold config
    objects) only for a file the user named, since that runs code from the file."""
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # noqa: BLE001 - e.g. OmegaConf objects in LaMa's hyper_parameters
        import warnings

        warnings.warn(
            f"{path}: not loadable with weights_only=True; unpickling it fully (trust the file)", stacklevel=2
        )
        return torch.load(path, map_location="cpu", weights_only=False)


class TracedInpainter:
    """Fast inference: frozen TorchScript traces of an eval-mode model, one per input shape.

    Single predictions run faster than in eager mode (less Python per layer), and the traces
    hold a channels-last copy of the weights, which the CPU convolutions run faster again, with
    the same probabilities to rounding. `traced(node_image)` takes the same
    (B, 1, H, W) batch as the model and returns probabilities; `predict` takes uint8 numpy
    images like `InpainterModel.predict`.
    """

    def __init__(self, model: InpainterModel) -> None:
        # A copy: converting the caller's model in place would change the layout of weights it may still train.
        self.model: InpainterModel = copy.deepcopy(model).eval().to(memory_format=torch.channels_last)  # type: ignore[call-overload]  # Module.to takes memory_format; torch's stub omits it
        self._traces: dict[tuple, torch.jit.ScriptModule] = {}

    def _trace(self, node_image: torch.Tensor) -> torch.jit.ScriptModule:
        key = (tuple(node_image.shape), node_image.dtype, node_image.device)
        if key not in self._traces:
            import warnings

            with warnings.catch_warnings(), torch.no_grad():
                warnings.simplefilter("ignore")  # shape checks become constants for this shape: intended
                self.model.check_size(node_image.shape[-2], node_image.shape[-1])
                self._traces[key] = torch.jit.freeze(torch.jit.trace(self.model, node_image, check_trace=False))
        return self._traces[key]

    def __call__(self, node_image: torch.Tensor) -> torch.Tensor:
        with torch.inference_mode():
            return self._trace(node_image)(node_image)

    def predict(self, observed: np.ndarray) -> np.ndarray:
        array = np.asarray(observed)
        single = array.ndim == 2
        batch = torch.from_numpy(np.ascontiguousarray(array[None] if single else array)).unsqueeze(1)
        probs = self(batch)[:, 0].float().cpu().numpy()
        return probs[0] if single else probs


# ----------------------------------------------------------------------------- export / load
def export_inpainter(generator: InpainterModel, path: str | Path, **extra: Any) -> Path:
    """Write `inpainter.pt`: {format, config, state_dict, ...extra}; atomic."""
    payload = {
        "format": INPAINTER_FORMAT,
        "config": generator.config.to_dict(),
        "state_dict": {k: v.detach().cpu().clone() for k, v in generator.state_dict().items()},
        "num_parameters": generator.num_parameters(),
        **extra,
    }
    return write_weights_file(payload, path)


def load_inpainter(
    path: str | Path, map_location: str | torch.device = "cpu"
) -> tuple[InpainterModel, InpainterConfig]:
    """An exported `inpainter.pt` (or a training checkpoint) -> (model in eval mode, config)."""
    return inpainter_from_payload(read_weights_file(path, "an inpainter export", map_location), path)


def inpainter_from_payload(payload: dict[str, Any], path: str | Path) -> tuple[InpainterModel, InpainterConfig]:
    """`load_inpainter` on a payload already read (`read_inpainter_export`), for callers that want its metadata too."""
    if export_kind(payload) == "policy":
        raise ValueError(f"{path}: a planner policy export, not an inpainter export")
    try:
        if "config" in payload and "state_dict" in payload:
            config = InpainterConfig.from_dict(payload["config"])
            state = payload["state_dict"]
        elif "hyper_parameters" in payload:  # a Lightning checkpoint of InpainterLightning
            config = InpainterConfig.from_dict(payload["hyper_parameters"]["model_config"])
            state = {k[len("generator.") :]: v for k, v in payload["state_dict"].items() if k.startswith("generator.")}
        else:
            raise ValueError("neither an exported inpainter nor an inpainter training checkpoint")
    except (KeyError, TypeError, ValueError) as error:  # e.g. a planner checkpoint: another model's config
        raise ValueError(f"{path}: not an inpainter export ({str(error)[:200]})") from None
    model = InpainterModel(config)
    model.load_state_dict(state)
    return model.eval(), config


def read_inpainter_export(path: str | Path) -> dict[str, Any]:
    """The whole exported payload (config, state_dict, metrics, history, timings)."""
    return read_weights_file(path, "an inpainter export")


def is_inpainter_export(payload: dict[str, Any]) -> bool:
    """Whether a checkpoint's dict is one of our `inpainter.pt` exports (`export_inpainter`)."""
    return payload.get("format") == INPAINTER_FORMAT and "config" in payload and "state_dict" in payload
