"""The network's pieces behave as the paper describes them, for every configuration."""
from __future__ import annotations

import itertools
import json

import pytest

torch = pytest.importorskip("torch")

from volsr_core.errors import InputError  # noqa: E402
from volsr_core.sr.checkpoint import load_model, save_checkpoint  # noqa: E402
from volsr_core.sr.network import (  # noqa: E402
    FEATURE_CHANNELS, NetworkConfig, Reweighting, SuperResolutionNet, backward_warp, upsample_motion, variant_config,
    zero_upsample,
)

FEATURE_SETS = [("color",), ("color", "depth"), ("color", "depth", "max_rgba"), ("color", "alpha", "depth", "max_rgba")]


def inputs(config: NetworkConfig, h: int = 8, w: int = 12, batch: int = 2):
    g = torch.Generator().manual_seed(0)
    frames = config.previous_frames + 1
    lr = torch.rand(batch, frames, config.in_channels, h, w, generator=g)
    motion = torch.randn(batch, frames, 2, h, w, generator=g)
    jitter = torch.rand(batch, frames, 2, generator=g) - 0.5
    return lr, motion, jitter


@pytest.mark.parametrize("scale, previous, variant, recurrent",
                         list(itertools.product((2, 4, 8, 16), range(4), "SML", (False, True))))
def test_output_shape_for_every_scale_history_and_variant(scale, previous, variant, recurrent):
    config = variant_config(variant, scale=scale, previous_frames=previous, recurrent=recurrent)
    net = SuperResolutionNet(config)
    lr, motion, jitter = inputs(config, h=4, w=6, batch=1)
    with torch.no_grad():
        out = net(lr, motion, jitter)
        assert out.shape == (1, 3, 4 * scale, 6 * scale)
        assert torch.isfinite(out).all()
        if recurrent:  # the first frame stands in the upscaled colour for the missing history
            base = torch.nn.functional.interpolate(lr[:, 0, :3], scale_factor=scale, mode="bilinear")
            assert torch.equal(net(lr, motion, jitter, base), out)
            assert not torch.equal(net(lr, motion, jitter, torch.zeros_like(out)), out)


@pytest.mark.parametrize("features", FEATURE_SETS)
def test_output_shape_for_every_feature_set(features):
    config = NetworkConfig(scale=4, previous_frames=2, features=features, fold=2)
    assert config.in_channels == sum(FEATURE_CHANNELS[f] for f in features)
    lr, motion, jitter = inputs(config)
    assert SuperResolutionNet(config)(lr, motion, jitter).shape == (2, 3, 32, 48)


@pytest.mark.parametrize("scale", (2, 4, 8))
def test_zero_upsampling_puts_each_sample_where_its_ray_went(scale):
    x = torch.arange(1, 1 + 2 * 3 * 5, dtype=torch.float32).reshape(1, 2, 3, 5)
    for jx, jy in [(-0.5, -0.5), (0.49, -0.2), (0.1, 0.3), (-0.26, 0.49)]:
        out = zero_upsample(x, torch.tensor([[jx, jy]]), scale)
        ox, oy = int(scale * (0.5 + jx)), int(scale * (0.5 + jy))
        assert torch.equal(out[:, :, oy::scale, ox::scale], x)
        assert int((out != 0).sum()) == x.numel()  # zeros everywhere else


def test_warping_with_zero_motion_is_the_identity_and_a_shift_moves_content():
    x = torch.rand(1, 3, 16, 20)
    assert torch.allclose(backward_warp(x, torch.zeros(1, 2, 16, 20)), x, atol=1e-6)
    shift = torch.zeros(1, 2, 16, 20)
    shift[:, 0], shift[:, 1] = 3.0, -2.0  # the point was 3 px right and 2 px up in the previous frame
    out = backward_warp(x, shift)
    assert torch.allclose(out[:, :, 2:, :-3], x[:, :, :-2, 3:], atol=1e-6)
    assert torch.all(out[:, :, :, -3:] == 0) and torch.all(out[:, :, :2] == 0)  # off screen


def test_motion_upsampling_scales_the_vectors():
    mv = torch.ones(1, 2, 4, 4) * torch.tensor([1.5, -0.5]).view(1, 2, 1, 1)
    up = upsample_motion(mv, 4)
    assert up.shape == (1, 2, 16, 16) and torch.allclose(up[0, 0], torch.full((16, 16), 6.0))


def test_reweighting_lies_in_zero_to_ten():
    net = Reweighting(12, 3)
    with torch.no_grad():
        for p in net.parameters():
            p.mul_(50)  # saturate the tanh both ways
        w = net(torch.randn(4, 12, 9, 9) * 10)
    assert w.shape == (4, 3, 9, 9)
    assert w.min() >= 0 and w.max() <= 10 and w.min() < 0.1 and w.max() > 9.9


@pytest.mark.parametrize("scale", (2, 4, 8))
def test_the_folded_fast_path_equals_zero_upsampling_warping_and_folding(scale):
    from volsr_core.sr.network import accumulated_flows, folded_previous, hr_stack, zero_upsample_folded

    def folded_stack(feats, jitter, flows, scale):
        """The fast path's frames in hr_stack's folded layout (B, C*s*s, h, w)."""
        b, _, c, h, w = feats.shape
        previous = [g.reshape(b, h, w, scale * scale, c).permute(0, 4, 3, 1, 2).reshape(b, c * scale * scale, h, w)
                    for g in folded_previous(feats, jitter, flows, scale)]
        return [zero_upsample_folded(feats[:, 0], jitter[:, 0], scale)] + previous

    g = torch.Generator().manual_seed(scale)
    feats = torch.rand(2, 3, 5, 6, 7, generator=g)
    jitter = torch.rand(2, 3, 2, generator=g) - 0.5
    flows = accumulated_flows([upsample_motion(torch.randn(2, 2, 6, 7, generator=g) * 1.5, scale) for _ in range(2)])
    fast = folded_stack(feats, jitter, flows, scale)
    slow = hr_stack(feats, jitter, flows, scale, scale)
    for a, b in zip(fast, slow):
        assert a.shape == b.shape
        assert torch.allclose(a, b, atol=1e-5)


def test_accumulated_flows_chain_the_frames_vectors():
    from volsr_core.sr.network import accumulated_flows

    m0 = torch.zeros(1, 2, 8, 8)
    m0[:, 0] = 1.0  # t -> t-1: one pixel right
    m1 = torch.zeros(1, 2, 8, 8)
    m1[:, 1] = -2.0  # t-1 -> t-2: two pixels up
    flow1, flow2 = accumulated_flows([m0, m1])
    assert torch.equal(flow1, m0)
    inside = (slice(None), slice(None), slice(None), slice(0, 6))  # where t-1's vectors are read on screen
    assert torch.allclose(flow2[inside][:, 0], torch.ones(1, 8, 6)) and torch.allclose(flow2[inside][:, 1],
                                                                                        torch.full((1, 8, 6), -2.0))


def concatenated_forward(net: SuperResolutionNet, lr, motion, jitter, history=None):
    """The network written plainly: zero-upsample, warp and fold every frame, concatenate, convolve."""
    from volsr_core.sr.network import accumulated_flows, hr_stack

    cfg = net.config
    s, d, n = cfg.scale, cfg.fold, cfg.previous_frames
    b, frames, c, h, w = lr.shape
    feats = net.features(lr.reshape(b * frames, c, h, w)).reshape(b, frames, -1, h, w)
    flows = accumulated_flows([upsample_motion(motion[:, k], s) for k in range(n)])
    stack = hr_stack(feats, jitter, flows, s, d)
    dd = d * d
    rgbd = [x[:, ch * dd:(ch + 1) * dd] for x in stack for ch in net.rgbd]
    base = torch.nn.functional.interpolate(lr[:, 0, :3], scale_factor=s, mode="bilinear", align_corners=False)
    if cfg.taau_base:
        base = history
        stack.append(torch.nn.functional.pixel_unshuffle(history, d) if d > 1 else history)
        rgbd.append(stack[-1])
    if cfg.recurrent:
        warped = backward_warp(history, upsample_motion(motion[:, 0], s))
        stack.append(torch.nn.functional.pixel_unshuffle(warped, d) if d > 1 else warped)
        rgbd.append(stack[-1])
    if cfg.weighted_inputs:
        weights = net.reweight(torch.cat(rgbd, 1))
        stack = [stack[0]] + [stack[k] * weights[:, k - 1:k] for k in range(1, len(stack))]
    out = torch.nn.functional.pixel_shuffle(net.reconstruct(torch.cat(stack, 1)), d)
    return out + base


@pytest.mark.parametrize("variant, scale, previous, features, recurrent, taau", [
    ("S", 4, 2, ("color", "depth", "max_rgba"), False, False), ("S", 2, 3, ("color", "alpha", "depth"), False, False),
    ("M", 4, 1, ("color", "depth", "max_rgba"), False, False), ("S", 8, 0, ("color",), False, False),
    ("S", 4, 1, ("color", "depth", "max_rgba"), True, False), ("S", 4, 0, ("color", "depth"), True, False),
    ("M", 4, 2, ("color", "depth", "max_rgba"), True, False), ("L", 4, 1, ("color", "depth"), True, False),
    ("S", 4, 0, ("color", "depth", "max_rgba"), False, True), ("M", 4, 1, ("color", "depth"), False, True)])
def test_the_split_first_layers_equal_the_concatenated_network(variant, scale, previous, features, recurrent, taau):
    net = SuperResolutionNet(variant_config(variant, scale, previous, features, recurrent, taau)).eval()
    with torch.no_grad():
        for p in net.parameters():  # break the symmetry of the default init: every weight matters
            p.add_(torch.randn_like(p) * 0.05)
        lr, motion, jitter = inputs(net.config, h=6, w=5)
        history = torch.rand(lr.shape[0], 3, 6 * scale, 5 * scale) if recurrent or taau else None
        assert torch.allclose(net(lr, motion, jitter, history),
                              concatenated_forward(net, lr, motion, jitter, history), atol=1e-4)


def test_a_taau_based_network_starts_as_taau_and_refines_it():
    net = SuperResolutionNet(variant_config("S", 4, 0, taau_base=True)).eval()
    lr, motion, jitter = inputs(net.config)
    taau = torch.rand(2, 3, 32, 48)
    with torch.no_grad():
        assert torch.equal(net(lr, motion, jitter, taau), taau), "a zero residual at initialisation"
        net.reconstruct.out.bias.fill_(0.1)
        assert torch.allclose(net(lr, motion, jitter, taau), taau + 0.1)
    with pytest.raises(ValueError, match="either its previous output"):
        variant_config("S", 4, 0, recurrent=True, taau_base=True)


def test_the_temporal_loss_is_zero_when_the_output_changes_as_the_ground_truth_does():
    from volsr_core.sr.losses import temporal_charbonnier

    g = torch.Generator().manual_seed(3)
    gt_prev, gt = torch.rand(1, 3, 16, 16, generator=g), torch.rand(1, 3, 16, 16, generator=g)
    motion = torch.zeros(1, 2, 16, 16)
    motion[:, 0] = 1.0
    offset = torch.rand(1, 3, 1, 1, generator=g)
    same = temporal_charbonnier(gt + offset, gt_prev + offset, gt, gt_prev, motion, eps=1e-6)
    assert same < 1e-5, "a constant error does not flicker"
    flicker = temporal_charbonnier(gt + offset, gt_prev, gt, gt_prev, motion, eps=1e-6)
    assert flicker > 0.1


def test_a_network_config_reads_back_from_its_dict_and_refuses_unknown_keys():
    config = NetworkConfig(scale=8, previous_frames=1, features=("color", "depth"), fold=4, widths=(8, 12))
    assert NetworkConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config
    assert NetworkConfig.from_dict({"scale": 2, "fold": 2}) == NetworkConfig(scale=2, fold=2)  # defaults filled
    with pytest.raises(InputError, match=r"^m.pt: network.colour: unknown key \(allowed: scale, previous_frames, "
                                         r"features, fold, widths, reweight_width, feature_width, recurrent, "
                                         r"taau_base, taau_aux, base_kernel, base_orientations, "
                                         r"taau_fine_sampling, taau_slabs\)$"):
        NetworkConfig.from_dict({**config.to_dict(), "colour": True}, source="m.pt", key="network")
    with pytest.raises(InputError, match=r"^m.pt: network.widths\[0\]: expected an integer, got str '8'$"):
        NetworkConfig.from_dict({"widths": ["8"]}, source="m.pt", key="network")
    with pytest.raises(InputError, match=r"^m.pt: network: scale must be one of \(2, 4, 8, 16\), got 3$"):
        NetworkConfig.from_dict({"scale": 3}, source="m.pt", key="network")


def test_a_weights_file_with_an_unknown_network_key_is_a_one_line_error(tmp_path):
    net = SuperResolutionNet(NetworkConfig(scale=4, previous_frames=0, recurrent=True, widths=(8, 12)))
    save_checkpoint(tmp_path / "m.pt", net)
    assert load_model(tmp_path / "m.pt").config == net.config
    payload = torch.load(tmp_path / "m.pt", weights_only=True)
    payload["network"]["colour"] = True
    torch.save(payload, tmp_path / "m.pt")
    with pytest.raises(InputError, match=r"m.pt: network.colour: unknown key \(allowed: scale, previous_frames,"):
        load_model(tmp_path / "m.pt")


def test_onnx_metadata_with_an_unknown_key_is_a_one_line_error(tmp_path):
    pytest.importorskip("onnxruntime")
    onnx = pytest.importorskip("onnx")
    from volsr_core.runtime.engines import METADATA_KEY, OnnxEngine
    from volsr_core.runtime.export import export_onnx

    net = SuperResolutionNet(variant_config("XS", 2, taau_base=True))  # the quickest to export: a filter, no U-Net
    path = export_onnx(net, tmp_path / "m.onnx", example_size=(4, 4))
    assert OnnxEngine(path, providers=["CPUExecutionProvider"]).config == net.config
    graph = onnx.load(path)
    (entry,) = [e for e in graph.metadata_props if e.key == METADATA_KEY]
    entry.value = json.dumps({**net.config.to_dict(), "colour": True})
    onnx.save(graph, path)
    with pytest.raises(InputError) as caught:
        OnnxEngine(path, providers=["CPUExecutionProvider"])
    assert str(caught.value) == (f"{path}: volsr.network.colour: unknown key (allowed: scale, previous_frames, "
                                 "features, fold, widths, reweight_width, feature_width, recurrent, taau_base, taau_aux, "
                                 "base_kernel, base_orientations, taau_fine_sampling, taau_slabs)")


# -- variant XS: a learned filter on the base --------------------------------------------------------
@pytest.mark.parametrize("scale", (2, 4))
def test_variant_xs_starts_as_taau_exactly_and_filters_the_bilinear_upscale_without_taau(scale):
    config = variant_config("XS", scale, previous_frames=2, taau_base=True, taau_aux=True)
    assert (config.widths, config.base_kernel, config.previous_frames, config.taau_aux) == ((), 2 * scale + 1, 0, False)
    net = SuperResolutionNet(config).eval()
    assert sum(p.numel() for p in net.parameters()) == config.base_orientations * (3 * (2 * scale + 1) ** 2 + 3)
    assert config.base_orientations == (2 if scale == 2 else 1)
    lr, motion, jitter = inputs(config, 7, 5, batch=1)[:3]
    history = torch.rand(1, config.history_channels, 7 * scale, 5 * scale)
    with torch.no_grad():
        assert torch.equal(net(lr, motion, jitter, history * 1.5), torch.clamp(history * 1.5, 0, 1)[:, :3])
        bilinear = torch.nn.functional.interpolate(lr[:, 0, :3], scale_factor=scale, mode="bilinear",
                                                   align_corners=False)
        plain = SuperResolutionNet(variant_config("XS", scale)).eval()
        assert torch.equal(plain(lr, motion, jitter), bilinear)


def test_a_network_without_a_u_net_needs_a_base_filter_and_no_previous_frames():
    with pytest.raises(ValueError, match="needs a learned base filter"):
        NetworkConfig(scale=2, previous_frames=0, fold=2, widths=(), taau_base=True)
    with pytest.raises(ValueError, match="no previous frames"):
        NetworkConfig(scale=2, previous_frames=1, fold=2, widths=(), base_kernel=5)
    with pytest.raises(ValueError, match="odd"):
        NetworkConfig(scale=2, previous_frames=0, fold=2, base_kernel=4)
    with pytest.raises(ValueError, match="base_orientations"):
        NetworkConfig(scale=2, previous_frames=0, fold=2, base_orientations=2)


def test_the_base_filter_learns_to_undo_a_known_blur():
    """Trained on pairs (blurred, sharp) of white noise, XS's filter must recover part of what a 3x3 box blur
    took: its error falls well below the blurred image's (the identity it starts as; measured 0.54 of it: the
    box blur loses some frequencies entirely, so no filter gets near 0)."""
    g = torch.Generator().manual_seed(0)
    net = SuperResolutionNet(variant_config("XS", 2, taau_base=True))
    optimizer = torch.optim.Adam(net.parameters(), lr=0.01)
    lr, motion, jitter = torch.zeros(8, 1, net.config.in_channels, 16, 16), torch.zeros(8, 1, 2, 16, 16), torch.zeros(8, 1, 2)
    inner = (..., slice(4, -4), slice(4, -4))

    def pair() -> tuple[torch.Tensor, torch.Tensor]:
        sharp = torch.rand(8, 3, 32, 32, generator=g)
        return sharp, torch.nn.functional.avg_pool2d(torch.nn.functional.pad(sharp, (1, 1, 1, 1), mode="replicate"), 3, 1)

    for _ in range(300):
        sharp, blurred = pair()
        loss = torch.mean((net(lr, motion, jitter, blurred) - sharp)[inner] ** 2)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    sharp, blurred = pair()
    with torch.no_grad():
        error = torch.mean((net(lr, motion, jitter, blurred) - sharp)[inner] ** 2)
    assert error < 0.7 * torch.mean((blurred - sharp)[inner] ** 2)
