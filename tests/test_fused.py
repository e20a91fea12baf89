"""The inference form of the network (network/fused.py): batch-norm folding, fused ReLUs and convolutions, the
chunked channels-last layout, each computing what the network as trained computes."""

from __future__ import annotations

import copy
from unittest import mock

import pytest
import torch
from torch.utils.flop_counter import FlopCounterMode

from refinenet.network.fused import (
    FUSED_RELU_DTYPES,
    Conv2dReLU,
    LinearReLU,
    SlidingMax,
    for_inference,
    fuse_batch_norm,
    inference_layout,
)
from refinenet.network.model import (
    PRECISIONS,
    NetworkConfig,
    RefineNet,
    count_parameters,
    example_inputs,
    preset,
    reduced_precision,
)


def _inputs(config: NetworkConfig, batch_size: int, seed: int = 0):
    return example_inputs(config, batch_size, torch.Generator().manual_seed(seed))


def _evaluated(**overrides) -> RefineNet:
    """A release-sized network in eval mode whose batch norms hold non-trivial statistics (three training steps'
    worth), so that folding them is tested on something other than the identity."""
    torch.manual_seed(0)
    model = RefineNet(preset("release", **overrides))
    for seed in range(3):
        model(*_inputs(model.config, 16, seed=seed))
    return model.eval()


def _with_and_without(fusion: str, precision: str) -> tuple[RefineNet, RefineNet]:
    """The inference form of one network with and without one of fused.py's fusions (`_fuse_relus`,
    `_fuse_convolutions`); skips where oneDNN's fused ops do not take the precision on this CPU."""
    if PRECISIONS[precision] not in FUSED_RELU_DTYPES:
        pytest.skip(f"oneDNN's fused ops do not take {precision} on this CPU")
    model = _evaluated()
    with mock.patch(f"refinenet.network.fused.{fusion}"):
        without = for_inference(copy.deepcopy(model), True, precision)
    return for_inference(model, True, precision), without


def test_fused_copy_for_inference_gives_the_same_normals():
    model = _evaluated()
    fused = fuse_batch_norm(model)
    assert not any(isinstance(m, torch.nn.BatchNorm1d) for m in fused.point_module.modules())
    remaining = [m for m in fused.modules() if isinstance(m, torch.nn.BatchNorm1d)]
    assert remaining == [fused.output_module[0]]  # the input BN precedes, not follows, its Linear
    inputs = _inputs(model.config, 5)
    with torch.no_grad():
        torch.testing.assert_close(fused(*inputs), model(*inputs), rtol=0, atol=1e-5)
    assert count_parameters(model) == 2_648_131  # the original is left as it was


@pytest.mark.parametrize("connection, at_once", [("weight", True), ("rot", False), ("concat", False)])
def test_the_inference_layout_computes_what_the_training_layout_does(connection, at_once):
    """Chunks of 64 patches, channels-last height maps and, for Refine-Net's connection only, the branches at once:
    150 patches (two full chunks and a part) give the normals of the whole batch at once, branch by branch, up to
    float32 rounding."""
    model = _evaluated(connection=connection)
    inputs = _inputs(model.config, 150)
    with torch.no_grad():
        reference = model(*inputs)
        laid_out = inference_layout(model)(*inputs)
    assert model.point_module.chunk == 64 and model.height_map_module.memory_format == torch.channels_last
    assert model.branches_at_once == at_once
    torch.testing.assert_close(laid_out, reference, rtol=0, atol=1e-5)


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
def test_the_fused_relus_give_the_network_of_the_two_layers_bit_for_bit(precision):
    """`LinearReLU` takes the place of every ReLU of a BN-folded point MLP (the 3 -> 64 layer included), runs
    oneDNN's fused op where the CPU has it, and the network's outputs equal those of Linear then ReLU exactly."""
    fused, two_layers = _with_and_without("_fuse_relus", precision)
    mlp = fused.point_module.mlp
    assert sum(isinstance(layer, LinearReLU) for layer in mlp) == 4 and type(mlp[-2]) is torch.nn.Linear
    assert not any(isinstance(layer, torch.nn.ReLU) for layer in mlp)
    inputs = _inputs(fused.config, 150)
    counter = FlopCounterMode(display=False, custom_mapping={torch.ops.mkldnn._linear_pointwise: lambda *a, **k: 1})
    with torch.inference_mode():
        expected = two_layers(*inputs)
        with counter:
            got = fused(*inputs)
    assert counter.get_flop_counts()["Global"][torch.ops.mkldnn._linear_pointwise] == 4 * 3  # 4 layers, 3 chunks
    assert torch.equal(got, expected)
    assert torch.equal(fused(*inputs).detach(), expected)  # with gradients enabled: the two layers themselves


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
def test_the_fused_convolutions_give_the_height_map_module_bit_for_bit(precision):
    """`Conv2dReLU` takes the place of every convolution and its ReLU, `SlidingMax` of every max-pool, and the
    network's outputs equal those of the layers as trained exactly."""
    fused, plain = _with_and_without("_fuse_convolutions", precision)
    maps = fused.height_map_module
    assert sum(isinstance(layer, Conv2dReLU) for layer in maps) == 5
    assert sum(isinstance(layer, SlidingMax) for layer in maps) == 2
    assert not any(isinstance(layer, torch.nn.ReLU | torch.nn.MaxPool2d) for layer in list(maps)[:maps.n_convolutional])
    inputs = _inputs(fused.config, 150)
    with torch.inference_mode():
        assert torch.equal(fused(*inputs), plain(*inputs))
    assert torch.equal(fused(*inputs).detach(), plain(*inputs).detach())  # with gradients: the layers themselves


@pytest.mark.parametrize("memory_format", [torch.contiguous_format, torch.channels_last])
def test_sliding_max_is_the_max_pool_of_stride_one(memory_format):
    x = torch.randn(4, 6, 9, 7).contiguous(memory_format=memory_format)
    x[0, 0, 2, 3] = float("nan")
    for k in (2, 3):
        assert torch.equal(SlidingMax(k)(x).isnan(), torch.nn.MaxPool2d(k, stride=1)(x).isnan())
        torch.testing.assert_close(SlidingMax(k)(x), torch.nn.MaxPool2d(k, stride=1)(x), rtol=0, atol=0,
                                   equal_nan=True)
    assert not SlidingMax.replaces(torch.nn.MaxPool2d(3)) and SlidingMax.replaces(torch.nn.MaxPool2d(3, stride=1))


@pytest.mark.parametrize("fuse, precision", [(True, "bfloat16"), (True, "float32"), (False, "bfloat16")])
def test_in_place_preparation_equals_the_copies(fuse, precision):
    """`for_inference` changes the loaded network itself and computes exactly what the copying forms give."""
    model = _evaluated()
    copied = inference_layout(reduced_precision(fuse_batch_norm(model) if fuse else model, precision))
    in_place = for_inference(model, fuse, precision)
    assert in_place is model
    inputs = _inputs(model.config, 8)
    with torch.no_grad():
        torch.testing.assert_close(in_place(*inputs), copied(*inputs), rtol=0, atol=0)
    with pytest.raises(ValueError, match="precision 'float16'"):
        for_inference(RefineNet(preset("release")), True, "float16")
