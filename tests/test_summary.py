"""[P] Table network_architecture from the model definition: the counts of docs/algorithm.md §8 and the paper's
two height-map modules (Refine-Net's, and the ablation's with a 256-channel last convolution and FC 512, 256, 192)."""

from dataclasses import replace

from settings import BASE

from refinenet.network.model import architecture
from refinenet.network.summary import hmp_columns, layers, parameters


def test_the_height_map_modules_and_parameter_counts():
    full = architecture(BASE.network, BASE.features, BASE.patches)
    ablation = architecture(replace(BASE.network, features="normals_hmps", connection="weight"), BASE.features,
                            BASE.patches)
    configs = {"full": full, "normals_hmps": ablation}
    assert parameters(configs)["full"] == 2_648_131  # docs/algorithm.md §8, points + HMPs, X = 9
    table = layers(configs)
    assert table.groupby("network")["params"].sum().to_dict() == parameters(configs)
    columns = hmp_columns(table, ["full", "normals_hmps"])
    assert columns["full"][:3] == ["conv 3x3, 64 (64x7x7)", "conv 3x3, 64 (64x7x7)", "max pool 3x3 (64x5x5)"]
    assert columns["normals_hmps"][-4:] == ["conv 3x3, 256 (256x3x3)", "FC 512", "FC 256", "FC 192"]
