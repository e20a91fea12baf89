"""[P] fig:syn / fig:insight: the normals of PCA, Jet, MFPS and Refine-Net as RGB and their angular errors as heat
maps on chosen test clouds (a PCPNet shape's scored points only: the network computed no others)."""

from refinenet import config
from refinenet.data.clouds import cloud_key, scored_points
from refinenet.data.io import read_cloud, read_normals
from refinenet.evaluation.figures import MAX_ERROR, Panel, normals_figure
from refinenet.evaluation.table import METHOD_NAMES
from refinenet.pipeline import stage
from refinenet.pipeline.workflow import FIGURE_METHODS, FIGURE_NORMALS, Pipeline


def arguments(parser):
    parser.add_argument("--clouds", nargs="+", required=True, help="the figure's test cloud records (.npz)")


def main(params, args):
    pipe = Pipeline(config.read_raw(args.params), args.params)
    panels = []
    for path in args.clouds:
        cloud = read_cloud(path)
        key, scored = cloud_key(path, cloud), scored_points(cloud.meta)
        rows = slice(None) if scored is None else scored
        estimates = {METHOD_NAMES[m]: read_normals(pipe.normals_path(m, key), len(cloud), scored)
                     for m in FIGURE_METHODS}
        panels.append(Panel(key.removeprefix("test/"), cloud.points[rows], cloud.normals[rows], estimates))
    d = params.data
    footer = (f"Profile {params.profile}; data: {d.source}" + (f" ({d.path})" if d.path else "")
              + f", {d.n_points} points per cloud. Unoriented angular error, heat map clipped at {MAX_ERROR:g} deg; "
              "orthographic view, azimuth 35, elevation 25 deg.")
    normals_figure(panels, footer, FIGURE_NORMALS)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
