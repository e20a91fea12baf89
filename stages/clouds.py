"""Make one cloud of the run: sample a procedural shape or mesh and add seeded noise, or read a given file."""

from refinenet.data.clouds import list_clouds, make_cloud
from refinenet.data.io import write_cloud
from refinenet.errors import ParamsError
from refinenet.pipeline import stage


def arguments(parser):
    parser.add_argument("--cloud", required=True, help="the cloud's key, <split>/<category>/<name>")
    parser.add_argument("--out", required=True)


def main(params, args):
    specs = {spec.key: spec for spec in list_clouds(params.data, params.noise)}
    if args.cloud not in specs:
        raise ParamsError("data", f"the run has no cloud '{args.cloud}'")
    write_cloud(args.out, make_cloud(specs[args.cloud], params.data.n_points, params.seed))


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
