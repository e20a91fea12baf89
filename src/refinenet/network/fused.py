"""A trained network in its inference form (docs/algorithm.md §8): batch norm folded into the Linear layers before
it, ReLUs fused into the products before them, the height maps channels-last with sliding maxima, the X branches
together, the feature modules in `model.PRECISIONS`. Each step keeps the outputs of `model.RefineNet` up to float
rounding; training keeps the plain network, whose gradients these layers do not carry."""

from __future__ import annotations

import copy
import functools

import torch
import torch.nn.functional as F
from torch import Tensor, nn
from torch.nn.utils.fusion import fuse_linear_bn_eval

from refinenet.network.model import HeightMapModule, RefineNet, check_precision, set_precision


def fuse_batch_norm(model: RefineNet) -> RefineNet:
    """An eval-mode copy for inference in which every BN that follows a Linear is folded into it.

    BN in eval mode is a per-channel affine map, so the outputs are equal up to float rounding; skipping the
    BN passes over the large per-point activations makes CPU inference 1.3-1.8x faster
    (benchmarks/results/inference.md). The copy must not be trained: its BN statistics are frozen in.
    """
    return _fold_batch_norm(copy.deepcopy(model).eval())


def _fold_batch_norm(model: RefineNet) -> RefineNet:
    for seq in model.modules():
        if isinstance(seq, nn.Sequential):
            for i in range(len(seq) - 1):
                if isinstance(seq[i], nn.Linear) and isinstance(seq[i + 1], nn.BatchNorm1d):
                    seq[i], seq[i + 1] = fuse_linear_bn_eval(seq[i], seq[i + 1]), nn.Identity()
    return model


#: Patches the point module takes at a time in inference: their P x 1024 products then stay in the cache, where a
#: whole batch's went to memory and back.
INFERENCE_CHUNK = 64


def for_inference(model: RefineNet, fuse: bool, precision: str) -> RefineNet:
    """`model` itself, a network its caller has just loaded and owns, made ready for inference in place: eval mode,
    BN folded where `fuse` (`fuse_batch_norm`), the feature modules in `precision` (`reduced_precision`), laid out
    by `inference_layout`. The copying forms deep-copy the network each time, which every inference job paid for
    every network."""
    check_precision(precision)
    model.eval()
    if fuse:
        _fold_batch_norm(model)
    inference_layout(model)
    return model if precision == "float32" else set_precision(model, precision)


def inference_layout(model: RefineNet) -> RefineNet:
    """`model` itself, set to compute the faster way without gradients: the point module INFERENCE_CHUNK patches at
    a time with its ReLUs fused into the products before them once BN is folded (`LinearReLU`), the height maps
    channels-last (oneDNN's faster layout for small maps) with their ReLUs fused into the convolutions
    (`Conv2dReLU`) and their max-pools as `SlidingMax`, and the X branches of Refine-Net's connection together
    (`RefineNet._all_branches`). The feature modules take half the time on a 2-core CPU, the connections a fifth;
    the outputs equal the training layout's up to float32 rounding (benchmarks/results/cli.md). Training keeps the
    default layout, which its gradients were tuned on."""
    model.branches_at_once = model.shares_weight_matrices
    if model.point_module is not None:
        model.point_module.chunk = INFERENCE_CHUNK
        _fuse_relus(model.point_module.mlp)
    if model.height_map_module is not None:
        model.height_map_module.memory_format = torch.channels_last
        _fuse_convolutions(model.height_map_module)
    return model


class LinearReLU(nn.Linear):
    """relu(linear(x)) in one pass where oneDNN can (a CPU, no gradients): its fused ReLU, bit for bit the same,
    saves the pass over the P x 64 activations, which takes as long as the small product itself and halves the point
    MLP's time before its last layer."""

    @classmethod
    def of(cls, linear: nn.Linear) -> LinearReLU:
        fused = cls(linear.in_features, linear.out_features, device="meta")
        fused.weight, fused.bias = linear.weight, linear.bias
        return fused

    def forward(self, x: Tensor) -> Tensor:
        if x.dtype in FUSED_RELU_DTYPES and x.device.type == "cpu" and not torch.is_grad_enabled():
            return torch.ops.mkldnn._linear_pointwise(x, self.weight, self.bias, "relu", [], "")
        return F.relu(super().forward(x))


class Conv2dReLU(nn.Conv2d):
    """relu(conv(x)) in one pass where oneDNN can (a CPU, no gradients): `LinearReLU`'s fusion for the height-map
    convolutions, bit for bit the same; a fifth less time for the convolutions in bfloat16."""

    @classmethod
    def of(cls, conv: nn.Conv2d) -> Conv2dReLU:
        fused = cls(conv.in_channels, conv.out_channels, conv.kernel_size, conv.stride, conv.padding, conv.dilation,
                    conv.groups, device="meta")
        fused.weight, fused.bias = conv.weight, conv.bias
        return fused

    def forward(self, x: Tensor) -> Tensor:
        if x.dtype in FUSED_RELU_DTYPES and x.device.type == "cpu" and not torch.is_grad_enabled():
            return torch.ops.mkldnn._convolution_pointwise(x, self.weight, self.bias, self.padding, self.stride,
                                                           self.dilation, self.groups, "relu", [], "")
        return F.relu(super().forward(x))


class SlidingMax(nn.Module):
    """A k x k max-pool of stride 1 and no padding as two passes of elementwise maxima, along rows then columns:
    the same values, in a quarter of the time of torch's pooling kernel on small channels-last maps (it also
    tracks the index of each maximum)."""

    def __init__(self, kernel_size: int):
        super().__init__()
        self.kernel_size = kernel_size

    @staticmethod
    def replaces(layer: nn.Module) -> bool:
        """Whether `layer` is a max-pool this module computes."""
        return isinstance(layer, nn.MaxPool2d) and isinstance(layer.kernel_size, int) and layer.stride == 1 \
            and layer.padding == 0 and layer.dilation == 1 and not layer.ceil_mode

    def forward(self, x: Tensor) -> Tensor:
        k = self.kernel_size
        rows = x.shape[2] - k + 1
        x = functools.reduce(torch.maximum, (x[:, :, i:i + rows] for i in range(k)))
        columns = x.shape[3] - k + 1
        return functools.reduce(torch.maximum, (x[:, :, :, j:j + columns] for j in range(k)))

    def extra_repr(self) -> str:
        return f"kernel_size={self.kernel_size}"


def _onednn_dtypes() -> tuple[torch.dtype, ...]:
    """The dtypes oneDNN's fused linear takes here: none without it, bfloat16 only where the CPU has it natively."""
    if not (torch.backends.mkldnn.is_available() and hasattr(torch.ops.mkldnn, "_linear_pointwise")):
        return ()
    return (torch.float32, torch.bfloat16) if torch.ops.mkldnn._is_mkldnn_bf16_supported() else (torch.float32,)


#: The dtypes in which `LinearReLU` runs oneDNN's fused op.
FUSED_RELU_DTYPES = _onednn_dtypes()


def _fuse_relus(mlp: nn.Sequential) -> None:
    """Each Linear of `mlp` that a ReLU follows, BN folded to an Identity between them, becomes a `LinearReLU`."""
    for i in range(len(mlp) - 2):
        if type(mlp[i]) is nn.Linear and isinstance(mlp[i + 1], nn.Identity) and isinstance(mlp[i + 2], nn.ReLU):
            mlp[i], mlp[i + 2] = LinearReLU.of(mlp[i]), nn.Identity()


def _fuse_convolutions(maps: HeightMapModule) -> None:
    """Each Conv2d of the height-map module's convolutional part becomes a `Conv2dReLU` and the ReLU after it an
    Identity (so that layers keep their places); each max-pool of stride 1 a `SlidingMax`."""
    for i in range(maps.n_convolutional):
        if type(maps[i]) is nn.Conv2d and isinstance(maps[i + 1], nn.ReLU):
            maps[i], maps[i + 1] = Conv2dReLU.of(maps[i]), nn.Identity()
        elif SlidingMax.replaces(maps[i]):
            maps[i] = SlidingMax(maps[i].kernel_size)
