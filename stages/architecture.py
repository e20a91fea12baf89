"""[P] Table network_architecture from the model definition: the height-map module of Refine-Net beside the one of
the normals&HMPs ablation, each network's parameter count, and every layer of both networks."""

from refinenet import config
from refinenet.network.model import architecture
from refinenet.network.summary import write_architecture
from refinenet.pipeline import stage
from refinenet.pipeline.catalogue import ARCHITECTURE
from refinenet.pipeline.layout import ARCHITECTURE_FILES
from refinenet.pipeline.workflow import Pipeline


def arguments(parser):
    pass


def main(params, args):
    pipe = Pipeline(config.read_raw(args.params), args.params)
    configs = {v: architecture(p.network, p.features, p.patches) for v, p in
               ((v, pipe.params[v]) for v in ARCHITECTURE)}
    full = configs[config.FULL]
    caption = (f"Height-map modules of Refine-Net and of the normals&HMPs ablation, generated from the model "
               f"definition: output shape per sample, parameters of one cluster's whole network. Profile "
               f"{params.profile}, {params.network.preset} preset, X = {full.n_normals}, m = {full.hmp_size}.")
    write_architecture(configs, ARCHITECTURE, caption, "table_architecture", ARCHITECTURE_FILES)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
