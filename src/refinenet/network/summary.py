"""The paper's Table network_architecture regenerated from the model definition: every layer of a network with
its output shape and parameter count (`model.architecture_table`), and the height-map module of Refine-Net beside
the one of the normals&HMPs ablation, in the paper's layout (one line per convolution, pooling and FC layer)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pandas as pd

from refinenet.atomic import atomic_path, write_text
from refinenet.evaluation.table import latex_escape
from refinenet.network.model import NetworkConfig, RefineNet, architecture_table, count_parameters

HMP_MODULE = "height_map_module."


def layers(configs: dict[str, NetworkConfig]) -> pd.DataFrame:
    """Every layer of each named network: network, layer, type, detail, output_shape, params."""
    frames = [pd.DataFrame(architecture_table(config)).assign(network=name) for name, config in configs.items()]
    table = pd.concat(frames, ignore_index=True)
    table["output_shape"] = ["x".join(map(str, shape)) for shape in table["output_shape"]]
    return table[["network", "layer", "type", "detail", "output_shape", "params"]]


def _describe(row: dict[str, Any]) -> str | None:
    """A layer as the paper writes it (conv 3x3, 64 / max pool 3x3 / FC 256); None for activations, norms,
    dropout and reshapes, which the paper's table leaves out."""
    shape = row["output_shape"]
    if row["type"] == "Conv2d":
        return f"conv 3x3, {shape.split('x')[0]} ({shape})"
    if row["type"] == "MaxPool2d":
        return f"max pool 3x3 ({shape})"
    if row["type"] == "Linear":
        return f"FC {shape}"
    return None


def hmp_columns(table: pd.DataFrame, networks: Sequence[str]) -> dict[str, list[str]]:
    """The height-map module of each network, one described layer per line."""
    columns = {}
    for name in networks:
        rows = table[(table["network"] == name) & table["layer"].str.startswith(HMP_MODULE)].to_dict("records")
        columns[name] = [text for text in map(_describe, rows) if text]
    return columns


def parameters(configs: dict[str, NetworkConfig]) -> dict[str, int]:
    """Parameters of one cluster's network, per named network."""
    return {name: count_parameters(RefineNet(config)) for name, config in configs.items()}


def write_architecture(configs: dict[str, NetworkConfig], titles: dict[str, str], caption: str, label: str,
                       paths: dict[str, str]) -> None:
    """paths: csv (the height-map modules side by side, and each network's parameters), tex (the same, booktabs),
    layers (every layer of every network)."""
    table = layers(configs)
    columns = hmp_columns(table, list(configs))
    counts = parameters(configs)
    depth = max(map(len, columns.values()))
    side = pd.DataFrame({titles[n]: [*col, *[""] * (depth - len(col)), f"{counts[n]:,} parameters"]
                         for n, col in columns.items()})
    with atomic_path(paths["layers"]) as tmp:
        table.to_csv(tmp, index=False)
    with atomic_path(paths["csv"]) as tmp:
        side.to_csv(tmp, index=False)
    lines = ["\\begin{table}[t]", "\\centering", f"\\caption{{{latex_escape(caption)}}}", f"\\label{{{label}}}",
             f"\\begin{{tabular}}{{{'l' * len(side.columns)}}}", "\\toprule",
             " & ".join(map(latex_escape, side.columns)) + " \\\\", "\\midrule"]
    for _, row in side.iloc[:-1].iterrows():
        lines.append(" & ".join(latex_escape(str(v)) for v in row) + " \\\\")
    lines += ["\\midrule", " & ".join(latex_escape(str(v)) for v in side.iloc[-1]) + " \\\\",
              "\\bottomrule", "\\end{tabular}", "\\end{table}", ""]
    write_text(paths["tex"], "\n".join(lines))
