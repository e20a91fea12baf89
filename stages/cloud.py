"""Make one cloud of the run: sample a procedural shape or mesh and add seeded noise, or read a given file."""

import argparse

from refinenet import stage
from refinenet.io import write_cloud
from refinenet.sources import CloudSpec, make_cloud


def main(args: argparse.Namespace) -> None:
    spec = CloudSpec(args.split, args.category, args.name, args.origin, args.noise)
    write_cloud(args.out, make_cloud(spec, args.n_points, args.seed))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--split", required=True, choices=["train", "test"])
    parser.add_argument("--category", required=True)
    parser.add_argument("--name", required=True)
    parser.add_argument("--origin", required=True, help="procedural shape name, mesh file or point file")
    parser.add_argument("--noise", type=float, default=None, help="noise sigma in %% of l_d (omit for given clouds)")
    parser.add_argument("--n-points", type=int, required=True)
    parser.add_argument("--seed", type=int, required=True, help="global seed")
    parser.add_argument("--out", required=True)
    stage.run(parser, main)
