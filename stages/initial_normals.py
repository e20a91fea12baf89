"""Estimate the initial normals of one cloud with MFPS (ALGORITHM.md §2) or its simple-MFPS ablation."""

import argparse

from refinenet import stage
from refinenet.errors import ParamsError
from refinenet.io import read_cloud, write_normals
from refinenet.mfps import MFPSConfig, mfps_normals


def main(args: argparse.Namespace) -> None:
    try:
        config = MFPSConfig(scales=tuple(args.scales), trials=args.trials, theta_t=args.theta_t, a_max=args.a_max,
                            eta=args.eta, simple=args.method == "simple_mfps", seed=args.seed)
    except ValueError as err:
        field, _, problem = str(err).removeprefix("MFPSConfig.").partition(": ")
        raise ParamsError(f"mfps.{field}", problem) from None
    cloud = read_cloud(args.cloud, min_points=max(config.scales[-1], config.k_bw))
    write_normals(args.out, mfps_normals(cloud.points, config, progress=args.progress, workers=args.threads))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--method", required=True, choices=["mfps", "simple_mfps"])
    parser.add_argument("--cloud", required=True)
    parser.add_argument("--scales", type=int, nargs="+", default=[50, 100, 150], help="K, patch sizes in points")
    parser.add_argument("--trials", type=int, default=150, help="R, random planes per patch")
    parser.add_argument("--theta-t", type=float, default=60.0, help="anisotropic angle (degrees)")
    parser.add_argument("--a-max", type=int, default=2, help="maximum size of the anisotropic set")
    parser.add_argument("--eta", choices=["code", "paper"], default="code", help="scale weight form")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--progress", action="store_true", help="show a progress bar per step")
    parser.add_argument("--out", required=True)
    stage.run(parser, main)
