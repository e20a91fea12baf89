"""The `refinenet` command: oriented Refine-Net normals for a user's own point cloud, with the shipped networks.

Heavy modules are imported after the arguments are parsed, so that `--threads` reaches BLAS, OpenMP and numba
before they start, and `refinenet --help` answers at once.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from pathlib import Path

from refinenet import interrupts
from refinenet.atomic import remove_temporaries
from refinenet.threads import limit_native_threads

EXIT_BAD_INPUT = 2
#: More threads than this only exhaust the machine (torch and OpenMP fail to start them, far from the user's input).
MAX_THREADS = 1024
ORIENTATIONS = ("mst", "viewpoint", "none")

EXAMPLES = """examples:
  refinenet normals scan.ply -o scan_normals.ply                 MFPS + Refine-Net, oriented by MST propagation
  refinenet normals street.xyz -o street.npy --orient viewpoint --viewpoint 0 0 2
  refinenet normals scan.ply -o scan.xyz --initial other_method.normals   refine another estimator's normals
  refinenet normals scan.pcd -o scan_pca.ply --method pca --orient none
  refinenet denoise scan_normals.ply -o scan_denoised.ply --surface scan_surface.ply
                                                                 move points along their normals (paper §Application)
  refinenet info                                                 provenance of the shipped networks

Inputs: .xyz/.txt (3 or 6 columns), .ply, .pcd, .npy (N x 3 or N x 6); only the files named are read.
Outputs by extension (any case): .ply/.pcd with normals, .xyz (+ .normals beside it), .txt or .npy (x y z nx ny
nz), .normals (normals only); the points go out exactly as they came in. No input is ever written, and an
existing output is replaced only with --force. Errors are one line, 'error: FILE: PROBLEM', with exit status 2
(130 or 143 when interrupted by SIGINT or SIGTERM); nothing is written then."""


class Parser(argparse.ArgumentParser):
    """An argument error in the one line of every other error (argparse would print the usage before it)."""

    def error(self, message: str):
        print(f"error: {message} (see `{self.prog} --help`)", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _interrupt(signum: int, _frame) -> None:
    """Stop at once on SIGINT or SIGTERM: remove the temporaries, say so in one line, and exit with 128 + the
    signal without unwinding, so that no thread of a pool runs on into the interpreter's shutdown. Inside an
    `interrupts.held` block (the final renames, a native reader) the signal waits for its end. (Nothing is
    imported here: the signal may come in the middle of an import.)"""
    if interrupts.is_held():
        interrupts.defer(signum)
        return
    remove_temporaries()
    os.write(2, f"error: interrupted by {signal.Signals(signum).name}; nothing was written\n".encode())
    os._exit(128 + signum)


def _written() -> None:
    """Once every output is in place, a signal ends the command as it ends any program: there is nothing to undo."""
    for sig in SIGNALS:
        signal.signal(sig, signal.SIG_DFL)


def finite(text: str) -> float:
    """A float option's value: NaN and infinities are refused where argparse's `float` takes them."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def parser() -> argparse.ArgumentParser:
    top = Parser(prog="refinenet", description=__doc__.split("\n")[0],
                                  formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EXAMPLES)
    commands = top.add_subparsers(dest="command", required=True)
    normals = commands.add_parser("normals", help="estimate the normals of a point cloud",
                                  formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EXAMPLES)
    normals.add_argument("input", help="the point cloud")
    normals.add_argument("-o", "--output", required=True, help="the file to write (format from its extension)")
    normals.add_argument("--method", default="refinenet", choices=("refinenet", "mfps", "pca", "jet"),
                         help="refinenet (default: MFPS refined by the networks), or an estimator alone")
    normals.add_argument("--initial", metavar="FILE",
                         help="normals of any estimator for Refine-Net to refine instead of MFPS (.normals, .npy, "
                              "or a point file with normals)")
    normals.add_argument("--orient", default="mst", choices=ORIENTATIONS,
                         help="mst: consistent along a minimum spanning tree, outwards on closed shapes (default); "
                              "viewpoint: towards --viewpoint; none: unoriented, as the paper evaluates")
    normals.add_argument("--viewpoint", type=finite, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                         help="sensor position for --orient viewpoint (default: the origin)")
    normals.add_argument("--scale", default="spacing", choices=("spacing", "diagonal"),
                         help="length unit of the radii: from the point spacing (default, any size and units) or "
                              "the bounding-box diagonal (the paper's, for whole objects)")
    normals.add_argument("--strata", default="auto", metavar="auto|S",
                         help="estimate the cloud as S interleaved random subsets, for a cloud denser than its noise "
                              "allows (auto: for refinenet as many as bring each subset's noise within what the "
                              "networks know, 1 for the other methods; 1: the whole cloud at once)")
    normals.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"),
                         help="where the networks run (auto: CUDA when present)")
    normals.add_argument("--precision", default="auto", choices=("auto", "float32", "bfloat16"),
                         help="of the networks' point MLP and height-map convolutions (auto: bfloat16 on a CPU that "
                              "computes it natively: about 1.5x faster, the mean error within 0.01 deg; else "
                              "float32, the pipeline's)")
    normals.add_argument("--threads", type=int, default=len(os.sched_getaffinity(0)),
                         help="CPU threads (default: every core this process may use)")
    normals.add_argument("--tile-points", type=int, default=None,
                         help="points per spatial tile; larger clouds are processed tile by tile (default 500000)")
    normals.add_argument("--release", metavar="FOLDER", help="a release exported by `snakemake release` "
                                                             "(default: the networks shipped with the package)")
    normals.add_argument("--timings", metavar="FILE.json", help="also write the wall and CPU seconds of each stage "
                                                                "(reading, MFPS, features, network, ...) to this file")
    normals.add_argument("--force", action="store_true", help="replace existing output files (never an input)")
    denoise = commands.add_parser("denoise", help="denoise a point cloud along its normals (docs/algorithm.md §11)",
                                  formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EXAMPLES)
    denoise.add_argument("input", help="the point cloud, with its normals unless --normals gives them")
    denoise.add_argument("-o", "--output", required=True, help="the denoised cloud and its normals (format from "
                                                               "its extension)")
    denoise.add_argument("--normals", metavar="FILE", help="the normals (.normals, .npy, or a point file with normals)")
    denoise.add_argument("--surface", metavar="MESH", help="also write the screened Poisson surface of the result "
                                                           "(.ply or .obj; needs oriented normals)")
    for name, help_text in (("radius", "ball radius of the neighbourhoods, in bounding-box diagonals"),
                            ("sigma", "width of the normal similarity"),
                            ("lam", "lambda, weight of the neighbours' normals"),
                            ("iterations", "point updates"), ("poisson-depth", "octree depth of --surface")):
        kind = int if name in ("iterations", "poisson-depth") else finite
        denoise.add_argument(f"--{name}", type=kind, help=f"{help_text} (default: the release's params)")
    denoise.add_argument("--release", metavar="FOLDER", help="the release whose denoise settings are the defaults")
    denoise.add_argument("--force", action="store_true", help="replace existing output files (never an input)")
    info = commands.add_parser("info", help="print the model card of the shipped networks")
    info.add_argument("--release", metavar="FOLDER", help="another release folder")
    return top


def main(argv: list[str] | None = None) -> int:
    """Run a command; every failure a user can cause ends in one line. SIGINT or SIGTERM ends the process at once,
    even when this is called from Python, with one line and the status 128 + the signal, nothing written. Only a
    bug of ours prints a traceback."""
    args = parser().parse_args(argv)
    if not 1 <= getattr(args, "threads", 1) <= MAX_THREADS:
        return _fail(f"--threads: must be 1 to {MAX_THREADS}, got {args.threads}")
    if args.command == "normals":
        limit_native_threads(args.threads)
    from refinenet.errors import RefineNetError

    handlers = {sig: signal.signal(sig, _interrupt) for sig in SIGNALS}
    try:
        return {"normals": normals, "denoise": denoise, "info": info}[args.command](args)
    except RefineNetError as err:
        return _fail(str(err))
    except OSError as err:  # one the readers and writers did not name: still the user's file or machine
        return _fail(f"{err.filename}: {err.strerror}" if err.filename else str(err))
    except MemoryError:
        return _fail("out of memory (for a cloud this large, try a smaller --tile-points)")
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


def _fail(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _release(args: argparse.Namespace, device: str = "cpu", with_networks: bool = True, precision: str = "float32"):
    from refinenet.network.release import SHIPPED, load_release

    return load_release(args.release or SHIPPED, device=device, with_networks=with_networks, precision=precision)


def info(args: argparse.Namespace) -> int:
    from refinenet.network.release import CARD_MD, SHIPPED

    card = Path(args.release or SHIPPED) / CARD_MD
    _release(args, with_networks=False)  # the card is only shown for a release that loads
    print(card.read_text(), end="")
    return 0


def normals(args: argparse.Namespace) -> int:
    import numpy as np
    import torch

    from refinenet.atomic import atomic_group, write_text
    from refinenet.cli.estimate import TILE_POINTS, auto_strata, estimate_normals, min_points
    from refinenet.data.io import POINT_FILE_SUFFIXES, check_file, output_files, read_cloud, write_points
    from refinenet.errors import InputError
    from refinenet.geometry.orientation import orient_mst, orient_viewpoint
    from refinenet.network.devices import resolve_device, resolve_precision
    from refinenet.profiling import recording, stage

    start = time.perf_counter()
    torch.set_num_threads(args.threads)
    check_file(args.input, POINT_FILE_SUFFIXES, "point file")
    output = Path(args.output)
    timings = Path(args.timings) if args.timings else None
    if timings is not None and timings.suffix.lower() != ".json":
        raise InputError(timings, "--timings writes JSON: name a .json file")
    _check_outputs(args, output_files(output) + ([timings] if timings else []), initial=args.initial)
    if args.initial and args.method != "refinenet":
        raise InputError(args.initial, f"--initial is refined by Refine-Net; it cannot be used with --method "
                                       f"{args.method}")
    if args.tile_points is not None and args.tile_points < 1:
        raise InputError("--tile-points", f"must be at least 1, got {args.tile_points}")
    if args.strata != "auto" and not (args.strata.isascii() and args.strata.isdigit() and int(args.strata) >= 1):
        raise InputError("--strata", f"must be 'auto' or a whole number of at least 1, got {args.strata!r}")
    try:
        device = resolve_device(args.device)
    except ValueError as err:
        raise InputError("--device", str(err)) from None
    precision = resolve_precision(args.precision, device)
    device = str(device)
    with recording() as stages:
        with stage("release"):
            release = _release(args, device, with_networks=args.method == "refinenet", precision=precision)
        needed = min_points(release.params, args.method, args.initial is not None)
        with stage("read"):
            cloud = read_cloud(args.input, min_points=needed)
            initial = _given_normals(args.initial, args.input, len(cloud)) if args.initial else None
        progress = sys.stderr.isatty()
        if args.strata == "auto":
            with stage("strata rule"):
                n_strata = auto_strata(cloud.points, release, args.method, initial is not None)
        elif len(cloud) // int(args.strata) < needed:
            raise InputError("--strata", f"{args.strata} subsets of {len(cloud):,} points have fewer than the "
                                         f"{needed} points of {args.method}'s largest neighbourhood")
        else:
            n_strata = int(args.strata)
        result = estimate_normals(cloud.points, release, args.method, initial, args.scale, device,
                                  args.tile_points or TILE_POINTS, args.threads, progress, n_strata)
        with stage("orientation"):
            if args.orient == "mst":
                result = orient_mst(cloud.points, result)
            elif args.orient == "viewpoint":
                result = orient_viewpoint(cloud.points, result, np.asarray(args.viewpoint))
        with atomic_group(_written):
            with stage("write"):
                write_points(output, cloud.points, result)
            if timings is not None:
                write_text(timings, json.dumps({
                    "input": args.input, "points": len(cloud), "method": args.method, "precision": precision,
                    "strata": n_strata, "threads": args.threads, "device": device,
                    "wall_s": time.perf_counter() - start, "stages": stages}, indent=1) + "\n")
    how = f"{precision} features, " if args.method == "refinenet" else ""
    how += f"{n_strata} strata, " if n_strata > 1 else ""
    print(f"{output}: {len(cloud):,} points, {args.method} normals ({how}{args.orient} orientation) in "
          f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


def _check_outputs(args: argparse.Namespace, writes: list[Path], **reads: str | None) -> None:
    """`files.check_outputs` for a command's input, its release and the other files named by `reads`."""
    from refinenet.cli.files import check_outputs, release_files
    from refinenet.network.release import SHIPPED

    named = {"the input": [args.input], "a file of the release": release_files(args.release or SHIPPED)}
    named |= {f"the --{option} file": [path] for option, path in reads.items() if path}
    check_outputs(named, writes, args.force)


def _given_normals(path: str, cloud_path: str, n_points: int):
    """Normals of `n_points` points from a normals file (.normals, .npy) or a point file with normals."""
    from refinenet.data.io import read_cloud, read_normals
    from refinenet.errors import InputError

    if Path(path).suffix.lower() == ".normals":
        return read_normals(path, n_points)
    normals = read_cloud(path).normals if Path(path).suffix.lower() != ".npy" else _npy_normals(path, n_points)
    if normals is None:
        raise InputError(path, "has no normals")
    if len(normals) != n_points:
        raise InputError(path, f"{len(normals)} normals for {n_points} points of {cloud_path}")
    return normals


def _npy_normals(path: str, n_points: int):
    """An N x 3 `.npy` of normals, or the normals of an N x 6 one (as `refinenet normals -o X.npy` writes)."""
    from refinenet.data.io import read_cloud, read_normals
    from refinenet.errors import InputError

    try:
        return read_normals(path, n_points)
    except InputError as err:
        try:
            normals = read_cloud(path).normals
        except InputError:
            normals = None
        if normals is None:
            raise err from None
        return normals


def denoise(args: argparse.Namespace) -> int:
    """The point update of [P] §Application along the given normals, and optionally the surface of the result."""
    from dataclasses import asdict, replace

    from refinenet.atomic import atomic_group, atomic_path
    from refinenet.config import validate_block
    from refinenet.data.io import (
        POINT_FILE_SUFFIXES,
        check_file,
        native_failure,
        native_output_captured,
        output_files,
        read_cloud,
        write_points,
    )
    from refinenet.data.noise import bbox_diagonal
    from refinenet.errors import InputError, OutputError
    from refinenet.evaluation.denoise import point_update, poisson_surface

    start = time.perf_counter()
    check_file(args.input, POINT_FILE_SUFFIXES, "point file")
    writes = output_files(args.output)
    if args.surface and Path(args.surface).suffix.lower() not in (".ply", ".obj"):
        raise OutputError(args.surface, "unsupported surface type (use .ply or .obj)")
    _check_outputs(args, writes + ([Path(args.surface)] if args.surface else []), normals=args.normals)
    if Path(args.output).suffix.lower() == ".normals":
        raise OutputError(args.output, "holds normals only, and denoising moves the points (use a point format)")
    settings = replace(_release(args, with_networks=False).params.denoise,
                       **{k: v for k, v in (("radius", args.radius), ("sigma", args.sigma), ("lam", args.lam),
                                            ("iterations", args.iterations), ("poisson_depth", args.poisson_depth))
                          if v is not None})
    validate_block("denoise", asdict(settings), "command line")
    cloud = read_cloud(args.input, min_points=3)
    normals = _given_normals(args.normals, args.input, len(cloud)) if args.normals else cloud.normals
    if normals is None:
        beside = Path(args.input).with_suffix(".normals")
        hint = f"--normals {beside}" if beside.is_file() else "--normals, or run `refinenet normals` first"
        raise InputError(args.input, f"has no normals: give them with {hint}")
    try:
        points = point_update(cloud.points, normals, settings.radius * bbox_diagonal(cloud.points), settings.sigma,
                              settings.lam, settings.iterations)
        surface = poisson_surface(points, normals, settings.poisson_depth) if args.surface else None
    except ValueError as err:
        raise InputError(args.normals or args.input, str(err)) from None
    with atomic_group(_written):
        write_points(args.output, points, normals)
        if surface is not None:
            import open3d as o3d

            mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(surface[0]),
                                             o3d.utility.Vector3iVector(surface[1]))
            with atomic_path(args.surface) as tmp:
                with native_output_captured() as messages:  # RPly reports a full disk here, not in the result
                    written = o3d.io.write_triangle_mesh(str(tmp), mesh)
                problem = native_failure(tmp, messages)
                if not written or problem:
                    raise OutputError(args.surface, f"cannot be written ({problem or 'Open3D failed'})")
    print(f"{args.output}: {len(cloud):,} points denoised ({settings.iterations} updates, radius {settings.radius} "
          f"l_d, sigma {settings.sigma}, lambda {settings.lam}) in {time.perf_counter() - start:.1f} s"
          + (f"; surface {args.surface}: {len(surface[1]):,} triangles" if surface is not None else ""),
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
