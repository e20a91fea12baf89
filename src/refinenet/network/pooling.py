"""The point module's max-pool over a patch's points fused with its last Linear layer and BN (docs/algorithm.md §8).

PointNet's last shared layer makes P x 1024 values per patch, of which the max-pool keeps 1024: computing BN on
all of them, and keeping them all for the backward pass, is most of the point module's cost. Here BN is applied
after the max (it is a per-channel affine map), its batch statistics come from those of the layer's input, and
gradients flow to the selected points alone, as through the max-pool itself.
"""

from __future__ import annotations

from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn


class PointBatchNorm(nn.BatchNorm1d):
    """BN of channels-last per-point features (B, P, C), with statistics over all B*P points, as BN after a
    1x1 convolution has."""

    def forward(self, x: Tensor) -> Tensor:
        return super().forward(x.reshape(-1, x.shape[-1])).view_as(x)


class _SelectedProducts(torch.autograd.Function):
    """`values` (C, J), the products x[rows[c, j]] . weight[c] already computed, with the gradients of those
    products: to weight[c] from its selected rows of x alone, and to x at those rows alone (the rest gets none)."""

    @staticmethod
    def forward(ctx: Any, x: Tensor, weight: Tensor, rows: Tensor, values: Tensor) -> Tensor:
        ctx.save_for_backward(x, weight, rows)
        return values.clone()

    @staticmethod
    def backward(ctx: Any, grad: Tensor) -> tuple[Tensor, Tensor, None, None]:
        x, weight, rows = ctx.saved_tensors
        grad = grad.to(weight.dtype).contiguous()
        selected = x.index_select(0, rows.reshape(-1)).view(*rows.shape, -1).to(grad.dtype)
        grad_weight = torch.bmm(grad.unsqueeze(1), selected).squeeze(1)
        products = (grad.unsqueeze(2) * weight.unsqueeze(1)).reshape(-1, x.shape[1])
        grad_x = torch.zeros_like(x).index_add_(0, rows.reshape(-1), products.to(x.dtype))
        return grad_x, grad_weight, None, None


def max_pool_linear_bn(x: Tensor, linear: nn.Linear, bn: nn.BatchNorm1d | nn.Identity) -> Tensor:
    """max over the P points of bn(linear(x)) for x (B, P, C_in) -> (B, C), without BN's passes over B x P x C.

    BN is a per-channel affine map (batch or running statistics), so its max over the points is its value at the
    point where linear(x) is largest (smallest where the scale is negative). The batch statistics of linear(x)
    follow from those of x: mean W mean(x) + b, variance diag(W cov(x) W^T). Only the product itself is computed
    at every point, to find the selected ones; gradients reach the selected points alone, as through a max-pool.
    A training step of the cpu profile's network takes 0.77x the time in float32 on CPU, 0.90x under bfloat16
    autocast (studies/results/point_pooling.md). `bn` is nn.Identity once folded into the Linear
    (`fuse_batch_norm`)."""
    batch, points, n_in = x.shape
    weight, bias = linear.weight, linear.bias
    flat = x.reshape(-1, n_in)
    center = shift = None
    if isinstance(bn, nn.Identity):
        scale = torch.ones_like(bias)
    elif bn.training:
        center, variance = _batch_statistics(flat, weight, bias)
        scale, shift = bn.weight / torch.sqrt(variance + bn.eps), bn.bias
        _update_running_statistics(bn, center, variance, len(flat))
    else:
        center = bn.running_mean
        scale, shift = bn.weight / torch.sqrt(bn.running_var + bn.eps), bn.bias
    differentiable = torch.is_grad_enabled() and (x.requires_grad or weight.requires_grad)
    with torch.no_grad():
        sign = torch.where(scale < 0, -1.0, 1.0).to(weight.dtype)
        signed = weight * sign.unsqueeze(1)
        if differentiable:
            # Products (B, C, P): the max and its index over contiguous points are several times faster than
            # over a strided axis.
            values, index = torch.matmul(signed, x.transpose(1, 2)).max(dim=2)
            rows = (index + torch.arange(batch, device=x.device).unsqueeze(1) * points).t().contiguous()
        else:  # the max alone: products (B, P, C), the faster layout for the matrix product (bfloat16's above all)
            values, rows = _max_over_points(F.linear(x, signed)), None
        values = values * sign
    if rows is not None:
        values = _SelectedProducts.apply(flat, weight, rows, values.t().contiguous()).t()
    y = values.to(bias.dtype) + bias
    if center is None:
        return y
    return (y - center) * scale + shift


def _max_over_points(products: Tensor) -> Tensor:
    """The max over dim 1 of (B, P, C) products. In bfloat16 torch's pooling kernel takes half the time of its amax
    on CPU (a quarter at P = 300), with the same values; in float32 amax is the faster."""
    if products.dtype == torch.bfloat16:
        return F.adaptive_max_pool1d(products.transpose(1, 2), 1).squeeze(2)
    return products.amax(dim=1)


def _batch_statistics(x: Tensor, weight: Tensor, bias: Tensor) -> tuple[Tensor, Tensor]:
    """Mean and (biased) variance over the rows of x W^T + b, in float32 at least whatever the autocast: from the
    mean and covariance of x (n x C_in), so that the n x C products need not be stored."""
    dtype = torch.promote_types(x.dtype, torch.float32)
    with torch.autocast(x.device.type, enabled=False):
        x, weight, bias = x.to(dtype), weight.to(dtype), bias.to(dtype)
        mean = x.mean(dim=0)
        centered = x - mean
        covariance = centered.t() @ centered / len(x)
        return mean @ weight.t() + bias, ((weight @ covariance) * weight).sum(dim=1)


def _update_running_statistics(bn: nn.BatchNorm1d, mean: Tensor, variance: Tensor, n: int) -> None:
    """What nn.BatchNorm1d does to its running statistics in a training pass (unbiased variance)."""
    if n < 2:
        raise ValueError(f"Expected more than 1 value per channel when training, got {n} points")
    with torch.no_grad():
        bn.num_batches_tracked.add_(1)
        momentum = bn.momentum if bn.momentum is not None else 1.0 / float(bn.num_batches_tracked)
        bn.running_mean.lerp_(mean.to(bn.running_mean.dtype), momentum)
        bn.running_var.lerp_((variance * n / (n - 1)).to(bn.running_var.dtype), momentum)
