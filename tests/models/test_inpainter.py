"""The FFC inpainter: shapes, input encoding, the spectral branch's global reach, Big-LaMa layout."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pipeline.models import (
    FFCResnetBlock,
    InpainterConfig,
    InpainterModel,
    TracedInpainter,
    encode_node_image,
    load_big_lama_generator,
    read_checkpoint,
)

TINY = InpainterConfig(ngf=4, n_blocks=1)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def node_batch(batch: int, size: int, seed: int = 0) -> torch.Tensor:
    rng = np.random.default_rng(seed)
    image = rng.choice(np.array([0, 128, 255], dtype=np.uint8), size=(batch, 1, size, size), p=[0.2, 0.6, 0.2])
    return torch.from_numpy(image)


@pytest.mark.parametrize("size", [32, 40, 48])
def test_forward_shape_and_range(size):
    torch.manual_seed(0)
    model = InpainterModel(TINY).eval()
    probs = model(node_batch(2, size))
    assert probs.shape == (2, 1, size, size)
    assert probs.dtype == torch.float32
    assert torch.all((probs > 0) & (probs < 1))
    single = model.predict(node_batch(1, size)[0, 0].numpy())
    assert single.shape == (size, size) and single.dtype == np.float32
    np.testing.assert_allclose(single, model(node_batch(1, size))[0, 0].detach().numpy(), atol=1e-6)


def test_traced_inference_matches_eager():
    torch.manual_seed(0)
    model = InpainterModel(TINY).eval()
    traced = TracedInpainter(model)
    for size in (32, 48, 32):
        image = node_batch(1, size, seed=size)[0, 0].numpy()
        np.testing.assert_allclose(traced.predict(image), model.predict(image), atol=1e-5)
    assert len(traced._traces) == 2  # one trace per shape, reused
    # The traces run on a channels-last copy; the caller's model keeps its own (contiguous) weights.
    assert all(w.is_contiguous() for w in model.parameters())
    assert any(w.dim() == 4 and not w.is_contiguous() for w in traced.model.parameters())
    with pytest.raises(ValueError, match="multiples of 8"):
        traced(node_batch(1, 20))


def test_size_must_be_a_multiple_of_eight():
    model = InpainterModel(TINY).eval()
    with pytest.raises(ValueError, match="multiples of 8"):
        model(node_batch(1, 36))


def test_default_config_is_small():
    model = InpainterModel(InpainterConfig())
    assert 10_000 < model.num_parameters() < 1_000_000


def test_input_encodings():
    image = torch.tensor([[[[255, 0], [128, 128]]]], dtype=torch.uint8)
    signed = encode_node_image(image, "signed", 2)
    assert signed[0, 0].tolist() == [[1, -1], [0, 0]] and signed[0, 1].tolist() == [[0, 0], [1, 1]]
    lama = encode_node_image(image, "lama", 4)
    assert lama.shape[1] == 4 and lama[0, 0].tolist() == [[1, 0], [0, 0]] and lama[0, 3].tolist() == [[0, 0], [1, 1]]
    onehot = encode_node_image(image, "onehot", 3)
    assert onehot.sum(1).eq(1).all()
    with pytest.raises(ValueError):
        InpainterConfig(input_encoding="signed", in_channels=3)


@pytest.mark.parametrize(
    "values, message",
    [
        (
            {"input_encoding": "signed", "in_channels": 3},
            "model: input_encoding 'signed' makes (2,) input channels, not in_channels=3",
        ),
        ({"input_encoding": "rgb"}, "model.input_encoding: must be one of 'signed', 'lama', 'onehot', got 'rgb'"),
        ({"ngf": 0}, "model.ngf: must be a whole number >= 1, got 0"),
        ({"n_blocks": -1}, "model.n_blocks: must be a whole number >= 0, got -1"),
        ({"ratio_gin": 1.5, "ratio_gout": 1.5}, "model.ratio_gin: must be a number in [0, 1], got 1.5"),
        (
            {"ratio_gin": 0.5},
            "model: ratio_gin and ratio_gout must be equal (the residual blocks add input and output)",
        ),
        (
            {"block_kernel_size": 4},
            "model.block_kernel_size: must be an odd kernel size (a convolution pads half of it on each side), got 4",
        ),
        (
            {"padding_type": "mirror"},
            "model.padding_type: must be one of 'reflect', 'zeros', 'replicate', 'circular', got 'mirror'",
        ),
        ({"enable_lfu": 1}, "model.enable_lfu: must be true or false, got 1"),
        ({"big_lama": "yes"}, "model.big_lama: must be true or false, got 'yes'"),
        (
            {"ngf_": 8},
            "model.ngf_: unknown setting (known: in_channels, out_channels, ngf, n_downsampling, n_blocks, "
            "max_features, init_ratio_g, downsample_ratio_g, ratio_gin, ratio_gout, enable_lfu, init_kernel_size, "
            "downsample_kernel_size, block_kernel_size, upsample_kernel_size, out_kernel_size, padding_type, "
            "fft_norm, input_encoding), got 8",
        ),
    ],
)
def test_a_bad_config_value_is_one_line_naming_its_key(values, message):
    with pytest.raises(ValueError) as refused:
        InpainterConfig.from_dict(values)
    assert str(refused.value) == message


def test_config_round_trips_through_its_dict():
    config = InpainterConfig.from_dict({"ngf": 8, "n_blocks": 1, "ratio_gin": 0, "ratio_gout": 0})
    assert config.ratio_gin == 0.0 and InpainterConfig.from_dict(config.to_dict()) == config
    assert InpainterConfig.from_dict(None) == InpainterConfig()
    big = InpainterConfig.from_dict({"big_lama": True, "in_channels": 4})  # the Big-LaMa layout, overridden
    assert big == InpainterConfig.big_lama(in_channels=4) and InpainterConfig.from_dict(big.to_dict()) == big


def test_spectral_branch_reaches_the_whole_image():
    """One pixel changed in a corner changes a residual block's output far away only through
    the global (Fourier) branch; a purely local block's 3x3 convolutions cannot reach there."""
    torch.manual_seed(0)
    x = torch.randn(1, 16, 32, 32)
    y = x.clone()
    y[:, :, 0, 0] += 5.0
    far = (slice(None), slice(None), slice(12, None), slice(12, None))
    for ratio, reaches in ((0.75, True), (0.0, False)):
        block = FFCResnetBlock(16, ratio, ratio).eval()
        cg = int(16 * ratio)
        with torch.no_grad():

            def run(t):
                out = block((t[:, : 16 - cg], t[:, 16 - cg :] if cg else None))
                return torch.cat([o for o in out if o is not None], dim=1)

            diff = (run(x) - run(y)).abs()
        assert (diff[far].max().item() > 1e-4) == reaches, (ratio, diff[far].max().item())


def test_a_few_steps_fit_a_batch():
    """The generator can learn: Adam steps on one batch reduce its BCE."""
    from torch.nn.functional import binary_cross_entropy_with_logits as bce

    torch.manual_seed(0)
    model = InpainterModel(TINY)
    x = node_batch(4, 32, seed=5)
    target = (torch.rand(4, 1, 32, 32) > 0.7).float()
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    losses = []
    for _ in range(15):
        loss = bce(model.forward_logits(x), target)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < losses[0]


# --------------------------------------------------------------------------- Big-LaMa layout
OFFICIAL_SHAPES = {  # from advimman/lama's FFCResNetGenerator with configs/training/big-lama.yaml
    "model.1.ffc.convl2l.weight": (64, 4, 7, 7),
    "model.1.bn_l.running_var": (64,),
    "model.2.ffc.convl2l.weight": (128, 64, 3, 3),
    "model.4.ffc.convl2l.weight": (128, 256, 3, 3),
    "model.4.ffc.convl2g.weight": (384, 256, 3, 3),
    "model.4.bn_g.weight": (384,),
    "model.5.conv1.ffc.convl2l.weight": (128, 128, 3, 3),
    "model.5.conv1.ffc.convg2l.weight": (128, 384, 3, 3),
    "model.5.conv1.ffc.convg2g.conv1.0.weight": (192, 384, 1, 1),
    "model.5.conv1.ffc.convg2g.conv1.1.running_mean": (192,),
    "model.5.conv1.ffc.convg2g.fu.conv_layer.weight": (384, 384, 1, 1),
    "model.5.conv1.ffc.convg2g.fu.bn.weight": (384,),
    "model.5.conv1.ffc.convg2g.conv2.weight": (384, 192, 1, 1),
    "model.22.conv2.bn_g.num_batches_tracked": (),
    "model.24.weight": (512, 256, 3, 3),
    "model.24.bias": (256,),
    "model.25.running_mean": (256,),
    "model.30.weight": (128, 64, 3, 3),
    "model.34.weight": (3, 64, 7, 7),
    "model.34.bias": (3,),
}


def test_big_lama_layout_save_and_reload(tmp_path):
    """The Big-LaMa config has the official state-dict layout (51 M parameters); official-shaped
    weights saved as a LaMa checkpoint load into our 2-in / 1-out model through the adapter."""
    torch.manual_seed(0)
    official = InpainterModel(InpainterConfig.big_lama(in_channels=4, out_channels=3, input_encoding="lama"))
    assert 50_500_000 < official.num_parameters() < 51_500_000
    state = official.state_dict()
    for key, shape in OFFICIAL_SHAPES.items():
        assert tuple(state[key].shape) == shape, key
    assert not any(k.startswith(("model.0.", "model.23.", "model.35.")) for k in state)  # pads, concat, sigmoid
    assert not any(".convg2g.lfu." in k or ".gate." in k for k in state)  # LFU off, not gated
    with torch.no_grad():  # non-default values, so that a copy is visible
        for key in ("model.5.conv1.ffc.convg2g.fu.bn.running_mean", "model.25.running_var"):
            state[key].uniform_(0.5, 1.5)
    path = tmp_path / "best.ckpt"
    torch.save(
        {
            "state_dict": {
                **{f"generator.{k}": v for k, v in state.items()},
                "discriminator.model0.0.weight": torch.zeros(3),
            }
        },
        path,
    )
    del official

    ours = InpainterModel(InpainterConfig.big_lama())
    summary = load_big_lama_generator(ours, read_checkpoint(path))
    assert summary["missing"] == [] and summary["unexpected"] == []
    loaded = ours.state_dict()
    first = state["model.1.ffc.convl2l.weight"]
    assert torch.equal(
        loaded["model.1.ffc.convl2l.weight"], torch.cat([first[:, :3].sum(1, keepdim=True), first[:, 3:]], 1)
    )
    assert torch.allclose(loaded["model.34.weight"], state["model.34.weight"].mean(0, keepdim=True))
    assert torch.allclose(loaded["model.34.bias"], state["model.34.bias"].mean().reshape(1))
    for key in (
        "model.5.conv1.ffc.convg2g.fu.conv_layer.weight",
        "model.5.conv1.ffc.convg2g.fu.bn.running_mean",
        "model.22.conv2.ffc.convl2g.weight",
        "model.25.running_var",
        "model.30.weight",
    ):
        assert torch.equal(loaded[key], state[key]), key


def test_adapter_preserves_the_official_computation():
    """With a grey node image, our adapted 2-in / 1-out net gives the mean of the official
    net's RGB logits (checked on a reduced width; the adapter is layout-generic)."""
    torch.manual_seed(0)
    small = dict(ngf=8, n_blocks=2)
    official = InpainterModel(InpainterConfig.big_lama(in_channels=4, out_channels=3, **small)).eval()
    ours = InpainterModel(InpainterConfig.big_lama(**small)).eval()
    load_big_lama_generator(ours, {f"generator.{k}": v for k, v in official.state_dict().items()})
    x = node_batch(2, 32, seed=4)
    with torch.no_grad():
        expected = official.forward_logits(x).mean(1, keepdim=True)
        got = ours.forward_logits(x)
    torch.testing.assert_close(got, expected, atol=1e-4, rtol=1e-4)


def test_adapter_rejects_other_layouts():
    official = InpainterModel(InpainterConfig.big_lama(in_channels=4, out_channels=3, ngf=8, n_blocks=1))
    with pytest.raises(ValueError, match="do not fit"):
        load_big_lama_generator(InpainterModel(TINY), {f"generator.{k}": v for k, v in official.state_dict().items()})
