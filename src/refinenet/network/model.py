"""The Refine-Net network (docs/algorithm.md §8): feature modules, per-branch connection modules, output module.

One network is trained per cluster. Each of the X branches refines one filtered normal v (in the local frame)
with what the feature modules learned from the point patch (refinement 1) and the height maps (refinement 2),
and the output module maps the concatenated branches to a unit normal in the local frame.

Where the paper [P] and the authors' release [C] disagree, `NetworkConfig` exposes the choice and the
presets `release` (default) and `paper` (docs/algorithm.md §14) pick a side; the other choices are fixed as §8
recommends and are noted in the docstring of the class that makes them.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from refinenet.config import FeatureConfig, NetworkParams, PatchConfig
from refinenet.errors import ParamsError
from refinenet.network.pooling import PointBatchNorm, max_pool_linear_bn

FEATURES = ("full", "normals", "normals_points", "normals_hmps")
CONNECTIONS = ("weight", "rot", "trans", "concat", "residual")
#: What the output module gives: the normal itself ([P], [C]), a correction to the first input normal, or a
#: weighted mean of the input normals plus a correction.
OUTPUTS = ("normal", "correction", "blend")
#: An untrained `blend` output's weight on the first input normal (the rest share what is left).
BLEND_FIRST_WEIGHT = 0.9

#: Per-point shared MLP of the point module (PointNet without T-Net).
POINT_MLP = (64, 64, 64, 128, 1024)
#: The two columns of [P] Table network_architecture: height-map module conv channels, FC hidden sizes.
HMP_ARCHITECTURES = {
    "refinenet": ((64, 64, 128, 128, 128), (256, 128)),
    "ablation": ((64, 64, 128, 128, 256), (512, 256)),
}
#: p, the size of the normal features: T_p is p x 3, T_h is p x p, and the normal FC is (p, p).
FEATURE_DIM = 64
#: [P]'s FC sizes for the "normals" ablation, which has no feature modules.
NORMALS_ONLY_FC = (256, 128)


@dataclass(frozen=True)
class NetworkConfig:
    """Everything that fixes the architecture of one per-cluster network; `PRESETS` name the two of §14, and
    `NetworkParams.config` builds the pipeline's from params.yaml."""

    n_normals: int
    """X, the filtered normals per point: 9 for synthetic data and PCPNet, 8 for real scans."""
    features: str
    """Feature modules: full (points + HMPs), normals, normals_points, normals_hmps ([P] ablations)."""
    connection: str
    """How a feature module refines a normal: weight (Refine-Net); rot, trans, concat, residual."""
    point_fc: tuple[int, ...]
    """Hidden FC sizes of the point module: [C] (512, 256), [P] (256, 128)."""
    output_fc: tuple[int, ...]
    """Hidden FC sizes of the output module: [C] (256, 128), [P] (512, 256). Not used by the normals
    ablation, which has [P]'s own sizes for it (NORMALS_ONLY_FC)."""
    dropout: float
    """Drop probability of every dropout layer ([C]; [P]'s "keep probability 0.3" is taken as this)."""
    hmp_size: int
    """m, the side of each height map."""
    n_patch_points: int
    """Points per patch: 100 in [C] (kNN), 300 in [P] (ball, padded). The network accepts any count."""
    hmp_architecture: str | None = None
    """Column of [P] Table network_architecture: refinenet or ablation; None: §8's choice for `features`."""
    output: str = "normal"
    """normal: the output module regresses the normal ([P], [C]). correction (beyond the paper): it regresses a
    vector added to the first input normal (the initial normal when X = 9) before normalisation, and starts at
    zero, so that an untrained network returns its input and training only has to learn the change. blend (beyond
    the paper): it also regresses a softmax weight per input normal and adds the correction to their weighted mean,
    so that where one input is right (a wide fit on a smooth surface, MFPS at an edge) the network can pick it
    instead of regressing the whole change; untrained, it returns almost its first input normal."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "point_fc", tuple(self.point_fc))
        object.__setattr__(self, "output_fc", tuple(self.output_fc))
        if self.n_normals < 1:
            raise ValueError(f"n_normals must be at least 1, got {self.n_normals}")
        if self.features not in FEATURES:
            raise ValueError(f"features '{self.features}' is not one of {FEATURES}")
        if self.connection not in CONNECTIONS:
            raise ValueError(f"connection '{self.connection}' is not one of {CONNECTIONS}")
        if self.output not in OUTPUTS:
            raise ValueError(f"output '{self.output}' is not one of {OUTPUTS}")
        if self.features == "normals" and self.connection != "weight":
            raise ValueError(f"connection '{self.connection}' needs a feature module, and 'normals' has none")
        for name in ("point_fc", "output_fc"):
            sizes = getattr(self, name)
            if not sizes or any(not isinstance(s, int) or s < 1 for s in sizes):
                raise ValueError(f"{name} must be a non-empty sequence of positive integers, got {sizes}")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"dropout is a drop probability in [0, 1), got {self.dropout}")
        if self.hmp_size < 5:
            raise ValueError(f"hmp_size must be at least 5 (two 3x3 stride-1 max-pools), got {self.hmp_size}")
        if self.n_patch_points < 1:
            raise ValueError(f"n_patch_points must be at least 1, got {self.n_patch_points}")
        if self.hmp_architecture not in (None, *HMP_ARCHITECTURES):
            raise ValueError(f"hmp_architecture '{self.hmp_architecture}' is not one of "
                             f"{tuple(HMP_ARCHITECTURES)}")

    @property
    def uses_points(self) -> bool:
        return self.features in ("full", "normals_points")

    @property
    def uses_hmps(self) -> bool:
        return self.features in ("full", "normals_hmps")

    @property
    def hmp_layout(self) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """(conv channels, FC hidden sizes) of the height-map module.

        §8: Refine-Net uses the left column of [P]'s table; the normals&HMPs ablation uses the right one.
        """
        default = "ablation" if self.features == "normals_hmps" else "refinenet"
        return HMP_ARCHITECTURES[self.hmp_architecture or default]


#: docs/algorithm.md §14: the release's sizes [C] and the paper's [P], for X = 9 normals and 7 x 7 height maps.
PRESETS = {
    "release": NetworkConfig(n_normals=9, features="full", connection="weight", point_fc=(512, 256),
                             output_fc=(256, 128), dropout=0.3, hmp_size=7, n_patch_points=100),
    "paper": NetworkConfig(n_normals=9, features="full", connection="weight", point_fc=(256, 128),
                           output_fc=(512, 256), dropout=0.3, hmp_size=7, n_patch_points=300),
}


def preset(name: str, **overrides: Any) -> NetworkConfig:
    """A named profile of docs/algorithm.md §14 (`release` = [C], `paper` = [P]) with some fields replaced."""
    if name not in PRESETS:
        raise ValueError(f"network preset '{name}' is not one of {tuple(PRESETS)}")
    return replace(PRESETS[name], **overrides)


def architecture(network: NetworkParams, features: FeatureConfig, patches: PatchConfig) -> NetworkConfig:
    """The pipeline's network: the preset and ablation choices of `network`, with X and m from the features
    block and the patch size from the patches block; a combination that makes no network is a ParamsError."""
    try:
        return preset(network.preset, features=network.features, connection=network.connection,
                      output=network.output, n_normals=features.n_normals, hmp_size=features.hmp_size,
                      n_patch_points=patches.size)
    except ValueError as err:
        raise ParamsError("network", str(err)) from None


def _fc(sizes: Sequence[int], dropout: float | None) -> list[nn.Module]:
    """Linear layers through `sizes`; every hidden layer gets BN, ReLU and, if `dropout` is given, Dropout."""
    layers: list[nn.Module] = []
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        layers.append(nn.Linear(n_in, n_out))
        if i < len(sizes) - 2:
            layers += [nn.BatchNorm1d(n_out), nn.ReLU()]
            if dropout is not None:
                layers.append(nn.Dropout(dropout))
    return layers


class PointModule(nn.Module):
    """Refinement 1's feature module: PointNet on the rotated, scaled patch (B, P, 3) -> (B, out_dim).

    The shared per-point MLP is written as Linear layers on channels-last points: the 1x1 convolution of [C]
    with the same parameters, and faster on CPU. BN follows every MLP layer, ReLU all but the last ([C]);
    then max-pool over the points (with the last layer and its BN, `max_pool_linear_bn`) and an FC head with BN,
    ReLU and Dropout.
    """

    def __init__(self, out_dim: int, hidden: Sequence[int], dropout: float):
        super().__init__()
        mlp: list[nn.Module] = []
        for i, (n_in, n_out) in enumerate(zip((3, *POINT_MLP[:-1]), POINT_MLP, strict=True)):
            mlp += [nn.Linear(n_in, n_out), PointBatchNorm(n_out)]
            if i < len(POINT_MLP) - 1:
                mlp.append(nn.ReLU())
        self.mlp = nn.Sequential(*mlp)
        self.fc = nn.Sequential(*_fc((POINT_MLP[-1], *hidden, out_dim), dropout))
        self.plain_pooling = False
        """True: every MLP layer runs on every point, then the max-pool (the definition, which
        `max_pool_linear_bn` equals; used where each layer's output must be seen, as by `architecture_table`)."""
        self.chunk: int | None = None
        """Patches the MLP and max-pool take at a time (None: the whole batch); set by `fused.inference_layout`."""

    def forward(self, points: Tensor) -> Tensor:
        dtype = points.dtype
        points = points.to(self.mlp[0].weight.dtype)
        if self.plain_pooling:
            pooled = self.mlp(points).amax(dim=1)
        elif self.chunk is None:
            pooled = self._pooled(points)
        else:
            pooled = torch.cat([self._pooled(part) for part in points.split(self.chunk)])
        return _in_precision(self.fc(pooled), self.mlp[0].weight, dtype)

    def _pooled(self, points: Tensor) -> Tensor:
        return max_pool_linear_bn(self.mlp[:-2](points), self.mlp[-2], self.mlp[-1])


class HeightMapModule(nn.Sequential):
    """Refinement 2's feature module: a CNN on the X stacked height maps (B, X, m, m) -> (B, out_dim).

    Layers per [P] Table network_architecture: 3x3 convolutions (padding 1) with ReLU and no BN, and 3x3
    stride-1 max-pools after the second and fourth; the FC head has BN, ReLU and Dropout like the point
    module's.
    """

    def __init__(self, n_normals: int, size: int, channels: Sequence[int], hidden: Sequence[int],
                 out_dim: int, dropout: float):
        convs: list[nn.Module] = []
        for i, (c_in, c_out) in enumerate(zip((n_normals, *channels[:-1]), channels, strict=True)):
            convs += [nn.Conv2d(c_in, c_out, kernel_size=3, padding=1), nn.ReLU()]
            if i in (1, 3):
                convs.append(nn.MaxPool2d(kernel_size=3, stride=1))
        flat = channels[-1] * (size - 4) ** 2
        super().__init__(*convs, nn.Flatten(), *_fc((flat, *hidden, out_dim), dropout))
        self.n_convolutional = len(convs)
        self.memory_format = torch.contiguous_format
        """Of the maps through the convolutions; set by `fused.inference_layout`."""

    def forward(self, heights: Tensor) -> Tensor:
        x = heights.to(self[0].weight.dtype).contiguous(memory_format=self.memory_format)
        for layer in self:
            x = layer(x)
        return _in_precision(x, self[0].weight, heights.dtype)


def _in_precision(out: Tensor, weight: Tensor, dtype: torch.dtype) -> Tensor:
    """A feature module's output in its input's `dtype` where the module itself computes in a lower precision
    (`reduced_precision`), so that the connections stay in float32. Under autocast (training in bfloat16) the
    weights are float32 and the output stays as autocast made it: the training that made the shipped networks."""
    return out.to(dtype) if weight.dtype != dtype else out


class Refinement(nn.Module):
    """One refinement step of a connection module: combines the branch feature u (in_dim) with the feature
    module's output t (feature_dim, the size the feature module is built for) into Y (out_dim)."""

    def __init__(self, in_dim: int, feature_dim: int, out_dim: int):
        super().__init__()
        self.in_dim, self.feature_dim, self.out_dim = in_dim, feature_dim, out_dim

    def extra_repr(self) -> str:
        return f"in_dim={self.in_dim}, feature_dim={self.feature_dim}, out_dim={self.out_dim}"


class WeightMatrix(Refinement):
    """Refine-Net's connection: t reshaped row-major to T (p x in_dim), Y = T u (p = 64)."""

    def __init__(self, in_dim: int):
        super().__init__(in_dim, FEATURE_DIM * in_dim, FEATURE_DIM)

    def forward(self, u: Tensor, t: Tensor) -> Tensor:
        return self.columns(u.unsqueeze(2), t).squeeze(2)

    def columns(self, u: Tensor, t: Tensor) -> Tensor:
        """Y = T u for each column of u (B, in_dim, X): one product for the X branches that share T."""
        return torch.bmm(t.view(-1, FEATURE_DIM, self.in_dim), u)


def quaternion_to_matrix(q: Tensor) -> Tensor:
    """Rotation matrices (B, 3, 3) of quaternions (B, 4) in (w, x, y, z) order, normalised first."""
    w, x, y, z = F.normalize(q, dim=1).unbind(1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=1).view(-1, 3, 3)


class RotationMatrix(Refinement):
    """[P]'s rotation option: t is a quaternion, Y = R(t) v. The identity quaternion is added to t (as in
    PCPNet's QSTN, §8) so that an untrained module starts near the identity."""

    def __init__(self) -> None:
        super().__init__(3, 4, 3)

    def forward(self, u: Tensor, t: Tensor) -> Tensor:
        rotation = quaternion_to_matrix(t + t.new_tensor([1.0, 0.0, 0.0, 0.0]))
        return torch.bmm(rotation, u.unsqueeze(2)).squeeze(2)


class TransformationMatrix(Refinement):
    """[P]'s transformation option: t reshaped row-major to M (3 x 3), Y = (M + I) v; the identity is added
    as §8 recommends, so that an untrained module passes v through."""

    def __init__(self) -> None:
        super().__init__(3, 9, 3)

    def forward(self, u: Tensor, t: Tensor) -> Tensor:
        matrix = t.view(-1, 3, 3) + torch.eye(3, dtype=t.dtype, device=t.device)
        return torch.bmm(matrix, u.unsqueeze(2)).squeeze(2)


class Concat(Refinement):
    """[P]'s concat ablation: t has the size of u, and Y = FC(64, 64)([u, t]). The FC is laid out like the
    normal FC (Linear, BN, ReLU, Linear) and is per branch, so branch sizes stay those of Refine-Net."""

    def __init__(self, in_dim: int):
        super().__init__(in_dim, in_dim, FEATURE_DIM)
        self.fc = nn.Sequential(*_fc((2 * in_dim, FEATURE_DIM, FEATURE_DIM), None))

    def forward(self, u: Tensor, t: Tensor) -> Tensor:
        return self.fc(torch.cat([u, t], dim=1))


class Residual(Refinement):
    """[P]'s residual ablation: t has the size of u, and Y = u + t. A normal-sized Y (3) is lifted by a
    per-branch Linear(3 -> 64) so that refinement 2 and the branch output keep Refine-Net's sizes (§8's
    choice; [P] is silent)."""

    def __init__(self, in_dim: int):
        super().__init__(in_dim, in_dim, FEATURE_DIM)
        self.lift = nn.Linear(in_dim, FEATURE_DIM) if in_dim != FEATURE_DIM else nn.Identity()

    def forward(self, u: Tensor, t: Tensor) -> Tensor:
        return self.lift(u + t)


def _refinement(connection: str, in_dim: int, first: bool) -> Refinement:
    """The step for `connection`; rot and trans only make sense on the normal itself, so a later refinement
    of their 3-d output uses the weight matrix (the HMP module then outputs 64 x 3, §8)."""
    if connection == "concat":
        return Concat(in_dim)
    if connection == "residual":
        return Residual(in_dim)
    if first and connection == "rot":
        return RotationMatrix()
    if first and connection == "trans":
        return TransformationMatrix()
    return WeightMatrix(in_dim)


class ConnectionModule(nn.Module):
    """One branch: refines its normal v by each feature module in turn and extends v itself by
    Z = FC(3 -> 64, BN, ReLU, 64). Output [Y1, (Y2,) Z]. Only the FC path (and the concat and residual
    ablations' layers) has per-branch weights; T_p and T_h are shared by all branches of a sample."""

    def __init__(self, connection: str, n_refinements: int):
        super().__init__()
        steps: list[Refinement] = []
        dim = 3
        for i in range(n_refinements):
            steps.append(_refinement(connection, dim, first=i == 0))
            dim = steps[-1].out_dim
        self.refinements = nn.ModuleList(steps)
        self.normal_fc = nn.Sequential(*_fc((3, FEATURE_DIM, FEATURE_DIM), None))

    @property
    def feature_dims(self) -> list[int]:
        """Output size each feature module must have, in refinement order."""
        return [step.feature_dim for step in self.refinements]

    @property
    def out_dim(self) -> int:
        return sum(step.out_dim for step in self.refinements) + FEATURE_DIM

    def forward(self, v: Tensor, features: Sequence[Tensor]) -> Tensor:
        ys, y = [], v
        for step, t in zip(self.refinements, features, strict=True):
            y = step(y, t)
            ys.append(y)
        return torch.cat([*ys, self.normal_fc(v)], dim=1)


class OutputModule(nn.Sequential):
    """Branches -> unit normal: BN on the input ([C]; kept in both presets, as the §8 parameter count of [P]'s
    sizes includes it), FC with BN, ReLU, Dropout, a final Linear to 3 (and X weights for `blend`), and L2
    normalisation. For `correction` and `blend` (NetworkConfig.output) the final Linear starts at zero and its
    3-vector is added to the first input normal, or to the weighted mean of the input normals, first."""

    def __init__(self, in_dim: int, hidden: Sequence[int], dropout: float, output: str = "normal",
                 n_normals: int = 1):
        weights = n_normals if output == "blend" else 0
        super().__init__(nn.BatchNorm1d(in_dim), *_fc((in_dim, *hidden, 3 + weights), dropout))
        self.output = output
        if output != "normal":
            nn.init.zeros_(self[-1].weight)
            nn.init.zeros_(self[-1].bias)
        if weights > 1:
            with torch.no_grad():
                self[-1].bias[3] = math.log(BLEND_FIRST_WEIGHT / (1 - BLEND_FIRST_WEIGHT) * (n_normals - 1))

    def forward(self, x: Tensor, normals: Tensor) -> Tensor:
        """`normals` (B, 3X): the input normals, each on its first's side."""
        y = super().forward(x)
        if self.output == "normal":
            return F.normalize(y, dim=1)
        if self.output == "correction":
            return F.normalize(y + normals[:, :3].to(y.dtype), dim=1)
        y = y.float()  # the mean of normals a degree apart needs more than bfloat16's 8 bits
        weights = torch.softmax(y[:, 3:], dim=1)
        mean = torch.einsum("bx,bxk->bk", weights, normals.float().reshape(len(y), -1, 3))
        return F.normalize(y[:, :3] + mean, dim=1)


class RefineNet(nn.Module):
    """The per-cluster network: (normals (B, 3X), points (B, P, 3), heights (B, X, m, m)) -> unit normals
    (B, 3), all in the local frame. Inputs a variant does not use may be None.

    The "normals" ablation has no feature or connection modules: [P] feeds the X concatenated normals to
    FC (256, 128, 3) laid out like the output module (§8 follows [P], not [C]'s per-branch FC).
    """

    def __init__(self, config: NetworkConfig):
        super().__init__()
        self.config = config
        n_refinements = int(config.uses_points) + int(config.uses_hmps)
        connections = [ConnectionModule(config.connection, n_refinements)
                       for _ in range(config.n_normals if n_refinements else 0)]
        # Points, when used, feed the first refinement and HMPs, when used, the last.
        dims = connections[0].feature_dims if connections else []
        self.point_module = None
        if config.uses_points:
            self.point_module = PointModule(dims[0], config.point_fc, config.dropout)
        self.height_map_module = None
        if config.uses_hmps:
            channels, hidden = config.hmp_layout
            self.height_map_module = HeightMapModule(config.n_normals, config.hmp_size, channels, hidden,
                                                     dims[-1], config.dropout)
        self.connections = nn.ModuleList(connections)
        self.branches_at_once = False
        """True: the branches are computed together (`_all_branches`); set by `fused.inference_layout`."""
        if connections:
            self.output_module = OutputModule(config.n_normals * connections[0].out_dim, config.output_fc,
                                              config.dropout, config.output, config.n_normals)
        else:
            self.output_module = OutputModule(3 * config.n_normals, NORMALS_ONLY_FC, config.dropout, config.output,
                                              config.n_normals)

    def forward(self, normals: Tensor, points: Tensor | None = None, heights: Tensor | None = None) -> Tensor:
        x = self.config.n_normals
        if normals.dim() != 2 or normals.shape[1] != 3 * x:
            raise ValueError(f"normals must have shape (B, {3 * x}), got {tuple(normals.shape)}")
        if not self.connections:
            return self.output_module(normals, normals)
        features = []
        if self.point_module is not None:
            if points is None or points.dim() != 3 or points.shape[2] != 3:
                raise ValueError(f"points must have shape (B, P, 3), got {_shape(points)}")
            features.append(self.point_module(points))
        if self.height_map_module is not None:
            m = self.config.hmp_size
            if heights is None or tuple(heights.shape[1:]) != (x, m, m):
                raise ValueError(f"heights must have shape (B, {x}, {m}, {m}), got {_shape(heights)}")
            features.append(self.height_map_module(heights))
        v = normals.reshape(-1, x, 3)
        if self.branches_at_once:
            branches = self._all_branches(v, features)
        else:
            branches = torch.cat([conn(v[:, b], features) for b, conn in enumerate(self.connections)], dim=1)
        return self.output_module(branches, normals)

    def _all_branches(self, v: Tensor, features: Sequence[Tensor]) -> Tensor:
        """What the X connection modules output, concatenated, when every refinement is a `WeightMatrix`: T_p and
        T_h are shared by the branches of a sample, so each refinement of the X normals v (B, X, 3) is one
        product of T with the matrix of their inputs, not X matrix-vector products."""
        y, ys = v.transpose(1, 2), []
        for step, t in zip(self.connections[0].refinements, features, strict=True):
            y = step.columns(y, t)
            ys.append(y.transpose(1, 2))
        z = torch.stack([conn.normal_fc(v[:, b]) for b, conn in enumerate(self.connections)], dim=1)
        return torch.cat([*ys, z], dim=2).reshape(len(v), -1)

    @property
    def shares_weight_matrices(self) -> bool:
        """Whether every refinement of every branch is a `WeightMatrix` (Refine-Net's connection)."""
        return bool(self.connections) and all(isinstance(step, WeightMatrix) for conn in self.connections
                                              for step in conn.refinements)


#: Inference precisions of the feature modules (`reduced_precision`).
PRECISIONS = {"float32": torch.float32, "bfloat16": torch.bfloat16}


def reduced_precision(model: RefineNet, precision: str) -> RefineNet:
    """An inference copy whose feature modules (the point module and the height-map module, FC heads included)
    compute in `precision`; the connection and output modules stay float32.

    The feature modules hold about 97% of the multiply-adds of a point, and where the CPU has native bfloat16
    (AVX512-BF16, AMX) they run about twice as fast in it. Their outputs pass through the connections and the
    output module, which absorb the rounding: over 100k points of a CAD shape the normals move from float32's by
    0.003 deg on average and the mean error by 0.0005 deg (benchmarks/results/cli.md). The connection and output
    modules, where bfloat16 does cost accuracy (+0.02 deg mean error with them in bfloat16 too), stay in float32.
    """
    check_precision(precision)
    return model if precision == "float32" else set_precision(copy.deepcopy(model).eval(), precision)


def check_precision(precision: str) -> None:
    """Raises for a precision not in PRECISIONS, before anything is changed."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision '{precision}' is not one of {tuple(PRECISIONS)}")


def set_precision(model: RefineNet, precision: str) -> RefineNet:
    """`model` itself with its feature modules cast to `precision` (`reduced_precision` casts a copy)."""
    for module in (model.point_module, model.height_map_module):
        if module is not None:
            module.to(PRECISIONS[precision])
    return model


def _shape(t: Tensor | None) -> tuple[int, ...] | None:
    return None if t is None else tuple(t.shape)


def example_inputs(config: NetworkConfig, batch_size: int, generator: torch.Generator | None = None,
                   device: torch.device | str | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """Random inputs of the right shapes (unit normals, points in the unit ball, heights in [-1, 1])."""
    x, m, p = config.n_normals, config.hmp_size, config.n_patch_points
    normals = F.normalize(torch.randn(batch_size, x, 3, generator=generator), dim=2).view(batch_size, 3 * x)
    points = F.normalize(torch.randn(batch_size, p, 3, generator=generator), dim=2)
    points = points * torch.rand(batch_size, p, 1, generator=generator)
    heights = 2 * torch.rand(batch_size, x, m, m, generator=generator) - 1
    return normals.to(device), points.to(device), heights.to(device)


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters (BN's affine weights included, running statistics not)."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def architecture_table(config: NetworkConfig) -> list[dict[str, Any]]:
    """One row per layer in execution order: layer (qualified name), type, detail, output_shape (per sample),
    params (the layer's own). Rows cover every leaf layer and every refinement step, so the params sum to
    `count_parameters` of the network; used to regenerate [P] Table network_architecture."""
    model = RefineNet(config).eval()
    if model.point_module is not None:
        model.point_module.plain_pooling = True
    rows: list[dict[str, Any]] = []

    def recorder(name: str):
        def hook(module: nn.Module, args: Any, output: Tensor) -> None:
            rows.append({
                "layer": name,
                "type": type(module).__name__,
                "detail": module.extra_repr(),
                "output_shape": tuple(output.shape[1:]),
                "params": sum(p.numel() for p in module.parameters(recurse=False)),
            })
        return hook

    handles = [module.register_forward_hook(recorder(name)) for name, module in model.named_modules()
               if name and (isinstance(module, Refinement) or not any(module.children()))]
    try:
        with torch.no_grad():
            model(*example_inputs(config, 1, torch.Generator().manual_seed(0)))
    finally:
        for handle in handles:
            handle.remove()
    return rows
