"""Simulate one range scan (docs/algorithm.md §1.5): a shape of params.yaml `scanner.shapes` seen by the virtual
depth camera from every viewpoint, its points and the exact normals of the surface points hit, written as a user's
scan would be (results/scans/<shape>.ply)."""

from refinenet import config
from refinenet.config import ScannerConfig
from refinenet.data.io import write_ply
from refinenet.data.noise import derive_seed
from refinenet.data.scans import simulate_scan
from refinenet.pipeline import stage


def arguments(parser):
    parser.add_argument("--shape", required=True, help="the shape scanned")
    parser.add_argument("--out", required=True, help="the .ply to write")


def main(params, args):
    scanner = ScannerConfig.from_resolved(config.resolve(config.read_raw(args.params), args.params), args.params)
    points, normals, _ = simulate_scan(args.shape, scanner, derive_seed(params.seed, "scan", args.shape))
    write_ply(args.out, points, normals)
    print(f"{args.shape}: {len(points):,} points from {scanner.views} viewpoints")


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
