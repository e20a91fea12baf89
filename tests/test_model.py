"""The network of docs/algorithm.md §8: exact parameter counts, layer shapes, variants, connection algebra."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from refinenet.network.model import (
    CONNECTIONS,
    FEATURES,
    NetworkConfig,
    RefineNet,
    RotationMatrix,
    TransformationMatrix,
    architecture_table,
    count_parameters,
    example_inputs,
    preset,
    quaternion_to_matrix,
    reduced_precision,
)
from refinenet.network.pooling import PointBatchNorm, max_pool_linear_bn

VARIANTS = [(f, c) for f in FEATURES for c in CONNECTIONS if f != "normals" or c == "weight"]


def _inputs(config: NetworkConfig, batch_size: int = 4, seed: int = 0):
    return example_inputs(config, batch_size, torch.Generator().manual_seed(seed))


@pytest.mark.parametrize(("config", "expected"), [
    # The §8 table ([C]'s architecture).
    (preset("release"), 2_648_131),
    (preset("release", features="normals_points"), 1_231_107),
    (preset("release", n_normals=8), 2_593_475),
    (preset("release", features="normals_hmps", hmp_architecture="refinenet"), 1_137_219),  # [C]'s normals&HMPs
    (preset("paper"), 2_804_163),
    # Derived by hand from the layer lists of §8.
    (preset("release", features="normals_hmps"), 2_293_571),  # right column: HMP 558,784 conv + 1,362,368 FC
    (preset("release", features="normals"), 41_273),  # BN(27) + 27-256-128-3 with BN
    (preset("release", connection="rot"), 1_954_557),  # point out 4, HMP out 64x3, branches of 3 + 64 + 64
])
def test_parameter_counts_match_the_spec(config: NetworkConfig, expected: int):
    assert count_parameters(RefineNet(config)) == expected


def test_parameter_count_per_module_of_the_full_network():
    model = RefineNet(preset("release"))
    assert count_parameters(model.point_module) == 858_688
    assert count_parameters(model.height_map_module) == 1_268_416
    assert count_parameters(model.connections) == 40_896
    assert count_parameters(model.output_module) == 480_131
    assert count_parameters(model.connections[0]) == 40_896 // 9


def test_presets():
    assert preset("release") == preset("release")
    paper = preset("paper", n_normals=8)
    assert (paper.point_fc, paper.output_fc) == ((256, 128), (512, 256))
    assert (paper.n_normals, paper.n_patch_points) == (8, 300)
    with pytest.raises(ValueError, match="preset"):
        preset("tensorflow")


@pytest.mark.parametrize("bad", [
    {"features": "points"}, {"connection": "add"}, {"output": "residual"}, {"features": "normals", "connection": "rot"},
    {"n_normals": 0}, {"point_fc": ()}, {"output_fc": (256, 0)}, {"dropout": 1.0}, {"dropout": -0.1},
    {"hmp_size": 4}, {"n_patch_points": 0}, {"hmp_architecture": "left"},
])
def test_invalid_configs_are_refused(bad: dict):
    with pytest.raises(ValueError):
        preset("release", **bad)


def test_sizes_from_yaml_lists_become_tuples():
    assert preset("release", point_fc=[256, 128]).point_fc == (256, 128)


def _hmp_rows(config: NetworkConfig) -> list[tuple[str, tuple[int, ...]]]:
    return [(row["type"], row["output_shape"]) for row in architecture_table(config)
            if row["layer"].startswith("height_map_module")
            and row["type"] in ("Conv2d", "MaxPool2d", "Linear")]


def test_architecture_table_reproduces_both_columns_of_the_paper_table():
    conv, pool, fc = "Conv2d", "MaxPool2d", "Linear"
    assert _hmp_rows(preset("release")) == [
        (conv, (64, 7, 7)), (conv, (64, 7, 7)), (pool, (64, 5, 5)), (conv, (128, 5, 5)), (conv, (128, 5, 5)),
        (pool, (128, 3, 3)), (conv, (128, 3, 3)), (fc, (256,)), (fc, (128,)), (fc, (64 * 64,))]
    assert _hmp_rows(preset("release", features="normals_hmps")) == [
        (conv, (64, 7, 7)), (conv, (64, 7, 7)), (pool, (64, 5, 5)), (conv, (128, 5, 5)), (conv, (128, 5, 5)),
        (pool, (128, 3, 3)), (conv, (256, 3, 3)), (fc, (512,)), (fc, (256,)), (fc, (64 * 3,))]


@pytest.mark.parametrize("config", [preset("release"), preset("paper"), preset("release", connection="concat")])
def test_architecture_table_accounts_for_every_parameter(config: NetworkConfig):
    rows = architecture_table(config)
    assert sum(row["params"] for row in rows) == count_parameters(RefineNet(config))
    assert {"layer", "type", "detail", "output_shape", "params"} <= set(rows[0])
    assert rows[-1]["output_shape"] == (3,)
    input_bn = next(row for row in rows if row["layer"] == "output_module.0")
    assert (input_bn["type"], input_bn["output_shape"]) == ("BatchNorm1d", (9 * 192,))


@pytest.mark.parametrize(("features", "connection"), VARIANTS)
def test_every_variant_trains_and_outputs_unit_normals(features: str, connection: str):
    torch.manual_seed(0)
    model = RefineNet(preset("release", features=features, connection=connection))
    out = model(*_inputs(model.config))
    assert out.shape == (4, 3)
    torch.testing.assert_close(out.norm(dim=1), torch.ones(4))
    out[:, 2].sum().backward()
    missing = [name for name, p in model.named_parameters() if p.grad is None]
    assert not missing


@pytest.mark.parametrize("connection", ["concat", "residual"])
def test_ablation_branches_keep_refinenet_sizes(connection: str):
    model = RefineNet(preset("release", connection=connection))
    assert model.connections[0].out_dim == 3 * 64


def test_eval_mode_is_deterministic_and_per_sample():
    torch.manual_seed(0)
    model = RefineNet(preset("release"))
    model(*_inputs(model.config, 8, seed=1))  # one training step's worth of BN statistics
    model.eval()
    normals, points, heights = _inputs(model.config, 5)
    with torch.no_grad():
        first, second = model(normals, points, heights), model(normals, points, heights)
        single = model(normals[:1], points[:1], heights[:1])
    assert torch.equal(first, second)
    torch.testing.assert_close(single, first[:1])


def test_reduced_precision_copy_computes_the_feature_modules_in_bfloat16():
    torch.manual_seed(0)
    model = RefineNet(preset("release")).eval()
    reduced = reduced_precision(model, "bfloat16")
    dtypes = {name: p.dtype for name, p in reduced.named_parameters()}
    low = {name for name, dtype in dtypes.items() if dtype == torch.bfloat16}
    assert low == {name for name in dtypes if name.startswith(("point_module.", "height_map_module."))}
    assert dtypes["point_module.fc.0.weight"] == dtypes["height_map_module.0.weight"] == torch.bfloat16
    assert dtypes["output_module.1.weight"] == torch.float32
    assert all(p.dtype == torch.float32 for p in model.parameters())  # the original is left as it was
    assert reduced_precision(model, "float32") is model
    inputs = _inputs(model.config, 64)
    with torch.no_grad():
        angles = torch.rad2deg(torch.arccos((reduced(*inputs) * model(*inputs)).sum(1).clamp(-1, 1)))
    assert reduced(*inputs).dtype == torch.float32 and angles.max() < 1.0, angles.max()
    with pytest.raises(ValueError, match="precision 'float16'"):
        reduced_precision(model, "float16")


def test_feature_modules_hand_the_connections_autocasts_dtype_in_training_and_float32_when_reduced():
    """Training in bfloat16 (autocast) passes the feature modules' bfloat16 outputs on, as the training that made
    the shipped networks did; only a copy lowered by `reduced_precision` casts them back to float32."""
    torch.manual_seed(0)
    model = RefineNet(preset("release"))
    seen: dict[str, torch.dtype] = {}

    def record(module):
        for name in ("point_module", "height_map_module"):
            getattr(module, name).register_forward_hook(lambda _m, _i, out, name=name: seen.update({name: out.dtype}))
        return module

    inputs = _inputs(model.config, 8)
    reduced = reduced_precision(model.eval(), "bfloat16")
    with torch.autocast("cpu", dtype=torch.bfloat16):
        record(model.train())(*inputs)
    assert seen == {"point_module": torch.bfloat16, "height_map_module": torch.bfloat16}
    with torch.no_grad():
        record(reduced)(*inputs)
    assert seen == {"point_module": torch.float32, "height_map_module": torch.float32}


def _pooling_layers(seed: int = 0) -> tuple[torch.nn.Linear, torch.nn.BatchNorm1d]:
    """The point module's last layer in float64, with some BN scales negative (where the max-pool selects the
    smallest product) and non-trivial running statistics."""
    torch.manual_seed(seed)
    linear, bn = torch.nn.Linear(16, 32).double(), PointBatchNorm(32).double()
    with torch.no_grad():
        bn.weight.uniform_(-1.0, 1.0)
        bn.bias.uniform_(-1.0, 1.0)
        bn.running_mean.uniform_(-0.5, 0.5)
        bn.running_var.uniform_(0.5, 2.0)
    return linear, bn


def _plain_pooling(x, linear, bn):
    return bn(linear(x)).amax(dim=1)


@pytest.mark.parametrize("training", [True, False])
def test_max_pool_linear_bn_equals_bn_then_max_pool_with_the_same_gradients(training: bool):
    x = torch.randn(6, 20, 16, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    grad = torch.randn(6, 32, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    results = []
    for pool in (_plain_pooling, max_pool_linear_bn):
        linear, bn = _pooling_layers()
        linear.train(training), bn.train(training)
        inputs = x.clone().requires_grad_(True)
        out = pool(inputs, linear, bn)
        out.backward(grad)
        results.append([out, inputs.grad, linear.weight.grad, linear.bias.grad, bn.weight.grad, bn.bias.grad,
                         bn.running_mean, bn.running_var, bn.num_batches_tracked])
    assert (results[1][4] != 0).all()  # every channel's BN scale got a gradient
    for plain, fast in zip(*results, strict=True):
        torch.testing.assert_close(fast, plain, rtol=1e-9, atol=1e-10)


def test_max_pool_linear_bn_of_a_folded_layer_is_the_max_pool_of_the_linear():
    linear, bn = _pooling_layers()
    linear.eval(), bn.eval()
    folded = torch.nn.utils.fusion.fuse_linear_bn_eval(linear, bn)
    x = torch.randn(6, 20, 16, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        fast = max_pool_linear_bn(x, folded, torch.nn.Identity())
        torch.testing.assert_close(fast, folded(x).amax(dim=1), rtol=1e-12, atol=1e-12)
        torch.testing.assert_close(fast, _plain_pooling(x, linear, bn), rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
def test_max_pool_linear_bn_without_gradients_is_bitwise_the_max_of_the_products(dtype):
    """The inference path's max over the points (a pooling kernel in bfloat16, amax in float32), the bias added
    after it."""
    linear = torch.nn.Linear(16, 64).to(dtype)
    x = torch.randn(5, 300, 16, generator=torch.Generator().manual_seed(3)).to(dtype)
    with torch.inference_mode():
        expected = torch.nn.functional.linear(x, linear.weight).amax(dim=1) + linear.bias
        assert torch.equal(max_pool_linear_bn(x, linear, torch.nn.Identity()), expected)


def test_weight_matrix_connection_computes_th_tp_v():
    torch.manual_seed(0)
    model = RefineNet(preset("release")).eval()
    normals, points, heights = _inputs(model.config, 3)
    branch = 4
    captured = {}
    hook = model.connections[branch].register_forward_hook(lambda m, args, out: captured.setdefault("y", out))
    with torch.no_grad():
        model(normals, points, heights)
        hook.remove()
        t_p = model.point_module(points).view(3, 64, 3)  # row-major 64 x 3
        t_h = model.height_map_module(heights).view(3, 64, 64)
        v = normals.view(3, 9, 3)[:, branch]
        y1 = torch.einsum("bij,bj->bi", t_p, v)
        y2 = torch.einsum("bij,bj->bi", t_h, y1)
        z = model.connections[branch].normal_fc(v)
    torch.testing.assert_close(captured["y"], torch.cat([y1, y2, z], dim=1))


def test_rotation_connection_starts_at_identity_and_stays_a_rotation():
    v = torch.nn.functional.normalize(torch.randn(6, 3), dim=1)
    torch.testing.assert_close(RotationMatrix()(v, torch.zeros(6, 4)), v)
    torch.testing.assert_close(TransformationMatrix()(v, torch.zeros(6, 9)), v)
    r = quaternion_to_matrix(torch.randn(6, 4))
    torch.testing.assert_close(r @ r.transpose(1, 2), torch.eye(3).expand(6, 3, 3))
    torch.testing.assert_close(torch.linalg.det(r), torch.ones(6))
    half_turn_about_z = quaternion_to_matrix(torch.tensor([[0.0, 0.0, 0.0, 2.0]]))
    torch.testing.assert_close(half_turn_about_z[0], torch.diag(torch.tensor([-1.0, -1.0, 1.0])))


def _learns(model: RefineNet, normals, points, heights) -> bool:
    """Whether 20 Adam steps on one fixed target cut the model's squared error tenfold."""
    model.train()
    target = torch.tensor([[0.0, 0.0, 1.0]]).expand(len(normals), 3)
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-2)
    errors = []
    for _ in range(20):
        optimiser.zero_grad()
        loss = (model(normals, points, heights) - target).pow(2).sum(dim=1).mean()
        loss.backward()
        optimiser.step()
        errors.append(loss.item())
    return errors[-1] < 0.1 * errors[0]


@pytest.mark.parametrize("features", ["full", "normals"])
def test_correction_output_starts_at_the_initial_normal_and_learns(features: str):
    torch.manual_seed(0)
    model = RefineNet(preset("release", features=features, output="correction"))
    assert count_parameters(model) == count_parameters(RefineNet(preset("release", features=features)))
    normals, points, heights = _inputs(model.config)
    torch.testing.assert_close(model(normals, points, heights), normals[:, :3])
    torch.testing.assert_close(model.eval()(normals, points, heights), normals[:, :3])
    assert _learns(model, normals, points, heights)


@pytest.mark.parametrize("features", ["full", "normals"])
def test_blend_output_starts_near_the_initial_normal_can_pick_an_input_and_learns(features: str):
    """blend: untrained, 0.9 of the first input normal and 0.01 of each of the other nine, normalised; X weights
    more in the last layer than correction; a dominant weight on one input returns that input; it learns a target."""
    torch.manual_seed(0)
    config = preset("release", features=features, output="blend")
    model = RefineNet(config)
    x, hidden = config.n_normals, model.output_module[-1].in_features
    correction = RefineNet(replace(config, output="correction"))
    assert count_parameters(model) == count_parameters(correction) + x * (hidden + 1)
    normals, points, heights = _inputs(config)
    v = normals.view(-1, x, 3)
    start = torch.nn.functional.normalize(0.9 * v[:, 0] + 0.1 / (x - 1) * v[:, 1:].sum(dim=1), dim=1)
    torch.testing.assert_close(model.eval()(normals, points, heights), start)
    with torch.no_grad():
        model.output_module[-1].bias[3 + 6] = 50.0
    torch.testing.assert_close(model(normals, points, heights), v[:, 6])
    assert _learns(model, normals, points, heights)


def test_missing_or_misshapen_inputs_are_named():
    model = RefineNet(preset("release"))
    normals, points, heights = _inputs(model.config)
    with pytest.raises(ValueError, match="normals"):
        model(normals[:, :24], points, heights)
    with pytest.raises(ValueError, match="points"):
        model(normals, None, heights)
    with pytest.raises(ValueError, match="heights"):
        model(normals, points, heights[:, :8])
    normals_only = RefineNet(preset("release", features="normals")).eval()
    assert normals_only(normals).shape == (4, 3)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_runs_on_cuda_under_no_grad():
    model = RefineNet(preset("release")).eval().cuda()
    inputs = example_inputs(model.config, 2, device="cuda")
    with torch.no_grad():
        out = model(*inputs)
    assert out.device.type == "cuda"
    reference = model.cpu()(*(t.cpu() for t in inputs))
    torch.testing.assert_close(out.cpu(), reference, rtol=0, atol=5e-3)  # cuDNN convolutions may use TF32

