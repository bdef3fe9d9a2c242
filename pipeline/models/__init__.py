"""Neural models: the Stage I node-image inpainter (LaMa's FFC ResNet generator) and the diffusion policy."""

from pipeline.models.big_lama import load_big_lama_generator
from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.models.configuration_inpainter import INPUT_ENCODINGS, InpainterConfig
from pipeline.models.modeling_diffusion import (
    DiffusionPolicy,
    GraphEncoder,
    NoisePredictionNet,
    TracedDenoiser,
    build_attention_mask,
    decode_actions,
    encode_actions,
)
from pipeline.models.modeling_inpainter import (
    FFC,
    FFC_BN_ACT,
    FFCResnetBlock,
    FourierUnit,
    InpainterModel,
    SpectralTransform,
    TracedInpainter,
    encode_node_image,
    read_checkpoint,
)

__all__ = [
    "DiffusionPolicy",
    "DiffusionPolicyConfig",
    "GraphEncoder",
    "NoisePredictionNet",
    "TracedDenoiser",
    "build_attention_mask",
    "decode_actions",
    "encode_actions",
    "FFC",
    "FFC_BN_ACT",
    "FFCResnetBlock",
    "FourierUnit",
    "INPUT_ENCODINGS",
    "InpainterConfig",
    "InpainterModel",
    "SpectralTransform",
    "TracedInpainter",
    "encode_node_image",
    "load_big_lama_generator",
    "read_checkpoint",
]
