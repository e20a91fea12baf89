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
from refinenet.threads import limit_native_threads, thread_independent_products

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


TILES_EXAMPLES = """examples (the steps workflow/tiles.smk runs, one job per tile):
  refinenet tiles plan scan.ply -o work/plan.json                 prints the number of jobs, N
  refinenet tiles run work/plan.json --job 0 -o work/0.npz       ... and so on to --job N-1, anywhere
  refinenet tiles merge work/plan.json work/*.npz -o scan_normals.ply

The normals are those of `refinenet normals` with the same options and --tile-points. Every job checks that the
cloud is the one the plan was made for."""


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
    _estimate_options(normals)
    _orientation_options(normals)
    _network_options(normals)
    normals.add_argument("--timings", metavar="FILE.json", help="also write the wall and CPU seconds of each stage "
                                                                "(reading, MFPS, features, network, ...) to this file")
    normals.add_argument("--force", action="store_true", help="replace existing output files (never an input)")
    tiles = commands.add_parser("tiles", help="the normals of one cloud as separate jobs, one per tile (for a "
                                              "cluster: workflow/tiles.smk runs them as Snakemake jobs)",
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=TILES_EXAMPLES)
    steps = tiles.add_subparsers(dest="step", required=True)
    plan = steps.add_parser("plan", help="measure what every tile takes from the whole cloud, and count the jobs")
    plan.add_argument("input", help="the point cloud")
    plan.add_argument("-o", "--output", required=True, metavar="PLAN.json", help="the plan to write")
    _estimate_options(plan)
    _threads_option(plan)
    run = steps.add_parser("run", help="the normals of one tile's own points")
    run.add_argument("plan", help="the plan of `refinenet tiles plan`")
    run.add_argument("--job", type=int, required=True, help="which job: 0 to the plan's n_jobs - 1")
    run.add_argument("-o", "--output", required=True, metavar="PIECE.npz", help="the piece to write")
    _network_options(run)
    merge = steps.add_parser("merge", help="the whole cloud's oriented normals from the pieces of every job")
    merge.add_argument("plan", help="the plan of `refinenet tiles plan`")
    merge.add_argument("pieces", nargs="+", metavar="PIECE.npz", help="the pieces of all jobs")
    merge.add_argument("-o", "--output", required=True, help="the file to write (format from its extension)")
    _orientation_options(merge)
    _threads_option(merge)
    for step in (plan, run, merge):
        step.add_argument("--force", action="store_true", help="replace existing output files (never an input)")
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


def _estimate_options(command: argparse.ArgumentParser) -> None:
    """What decides the normals before the networks run: the method, its start, the unit, strata and tiles."""
    command.add_argument("--method", default="refinenet", choices=("refinenet", "mfps", "pca", "jet"),
                         help="refinenet (default: MFPS refined by the networks), or an estimator alone")
    command.add_argument("--initial", metavar="FILE",
                         help="normals of any estimator for Refine-Net to refine instead of MFPS (.normals, .npy, "
                              "or a point file with normals)")
    command.add_argument("--scale", default="spacing", choices=("spacing", "diagonal"),
                         help="length unit of the radii: from the point spacing (default, any size and units) or "
                              "the bounding-box diagonal (the paper's, for whole objects)")
    command.add_argument("--strata", default="auto", metavar="auto|S",
                         help="estimate the cloud as S interleaved random subsets, for a cloud denser than its noise "
                              "allows (auto: for refinenet as many as bring each subset's noise within what the "
                              "networks know, 1 for the other methods; 1: the whole cloud at once)")
    command.add_argument("--tile-points", type=int, default=None,
                         help="points per spatial tile; larger clouds are processed tile by tile (default 500000)")
    command.add_argument("--release", metavar="FOLDER", help="a release exported by `snakemake release` "
                                                             "(default: the networks shipped with the package)")


def _orientation_options(command: argparse.ArgumentParser) -> None:
    command.add_argument("--orient", default="mst", choices=ORIENTATIONS,
                         help="mst: consistent along a minimum spanning tree, outwards on closed shapes (default); "
                              "viewpoint: towards --viewpoint; none: unoriented, as the paper evaluates")
    command.add_argument("--viewpoint", type=finite, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                         help="sensor position for --orient viewpoint (default: the origin)")


def _network_options(command: argparse.ArgumentParser) -> None:
    """Where and how the work runs; these change the normals only within the precision's rounding."""
    command.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"),
                         help="where the networks run (auto: CUDA when present)")
    command.add_argument("--precision", default="auto", choices=("auto", "float32", "bfloat16"),
                         help="of the networks' feature modules (auto: bfloat16 on a CPU that "
                              "computes it natively: about 1.5x faster, the mean error within 0.01 deg; else "
                              "float32, the pipeline's)")
    _threads_option(command)


def _threads_option(command: argparse.ArgumentParser) -> None:
    command.add_argument("--threads", type=int, default=len(os.sched_getaffinity(0)),
                         help="CPU threads (default: every core this process may use)")


def main(argv: list[str] | None = None) -> int:
    """Run a command; every failure a user can cause ends in one line. SIGINT or SIGTERM ends the process at once,
    even when this is called from Python, with one line and the status 128 + the signal, nothing written. Only a
    bug of ours prints a traceback."""
    args = parser().parse_args(argv)
    if not 1 <= getattr(args, "threads", 1) <= MAX_THREADS:
        return _fail(f"--threads: must be 1 to {MAX_THREADS}, got {args.threads}")
    if args.command in ("normals", "tiles"):
        limit_native_threads(args.threads)
        thread_independent_products()
    from refinenet.errors import RefineNetError

    handlers = {sig: signal.signal(sig, _interrupt) for sig in SIGNALS}
    try:
        handler = {"normals": normals, "denoise": denoise, "info": info}.get(args.command)
        return handler(args) if handler else {"plan": plan, "run": run, "merge": merge}[args.step](args)
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


def _release(folder: str | None, device: str = "cpu", with_networks: bool = True, precision: str = "float32"):
    from refinenet.network.release import SHIPPED, load_release

    return load_release(folder or SHIPPED, device=device, with_networks=with_networks, precision=precision)


def info(args: argparse.Namespace) -> int:
    from refinenet.network.release import CARD_MD, SHIPPED

    card = Path(args.release or SHIPPED) / CARD_MD
    _release(args.release, with_networks=False)  # the card is only shown for a release that loads
    print(card.read_text(), end="")
    return 0


def normals(args: argparse.Namespace) -> int:
    """`refinenet normals`. Everything that needs no network is checked first, the cloud read included, so that a
    bad input is refused in a fraction of a second, before torch and the estimators are imported."""
    from refinenet.atomic import atomic_group, write_text
    from refinenet.data.io import POINT_FILE_SUFFIXES, check_file, output_files, read_cloud, write_points
    from refinenet.profiling import recording, stage

    start = time.perf_counter()
    check_file(args.input, POINT_FILE_SUFFIXES, "point file")
    output = Path(args.output)
    timings = Path(args.timings) if args.timings else None
    if timings is not None:
        _check_suffix(timings, ".json", "--timings writes JSON")
    _check_outputs(args.input, args.release, output_files(output) + ([timings] if timings else []), args.force,
                   {"the --initial file": args.initial})
    _check_estimate_options(args)
    with recording() as stages:
        with stage("read"):
            cloud = read_cloud(args.input)
            initial = _given_normals(args.initial, args.input, len(cloud)) if args.initial else None
        import torch

        from refinenet.cli.estimate import TILE_POINTS, estimate_normals

        torch.set_num_threads(args.threads)
        device, precision = _device(args)
        with stage("release"):
            release = _release(args.release, device, with_networks=args.method == "refinenet", precision=precision)
        needed = _needed(args, len(cloud), release)
        n_strata = _n_strata(args, cloud.points, release, needed)
        result = estimate_normals(cloud.points, release, args.method, initial, args.scale, device,
                                  args.tile_points or TILE_POINTS, args.threads, sys.stderr.isatty(), n_strata)
        result = _oriented(args, cloud.points, result)
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


def plan(args: argparse.Namespace) -> int:
    """`refinenet tiles plan`: the whole-cloud measurements of `normals`, stopped before the first tile."""
    from refinenet.atomic import atomic_group, write_text
    from refinenet.data.io import POINT_FILE_SUFFIXES, check_file, read_cloud

    start = time.perf_counter()
    check_file(args.input, POINT_FILE_SUFFIXES, "point file")
    output = Path(args.output)
    _check_suffix(output, ".json", "the plan is JSON")
    _check_outputs(args.input, args.release, [output], args.force, {"the --initial file": args.initial})
    _check_estimate_options(args)
    cloud = read_cloud(args.input)
    if args.initial:
        _given_normals(args.initial, args.input, len(cloud))  # refused here, not in every job
    from refinenet.cli.estimate import TILE_POINTS
    from refinenet.cli.jobs import make_plan

    release = _release(args.release, with_networks=False)
    needed = _needed(args, len(cloud), release)
    n_strata = _n_strata(args, cloud.points, release, needed)
    absolute = {name: os.path.abspath(path) if path else None
                for name, path in (("cloud", args.input), ("release", args.release), ("initial", args.initial))}
    made = make_plan(cloud.points, absolute["cloud"], release, args.method, n_strata, absolute["release"],
                     absolute["initial"], args.scale, args.tile_points or TILE_POINTS)
    with atomic_group(_written):
        write_text(output, made.to_json())
    print(f"{output}: {made.n_jobs} jobs ({n_strata} strata of {', '.join(map(str, made.n_tiles))} tiles) for "
          f"{len(cloud):,} points in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    print(made.n_jobs)
    return 0


def run(args: argparse.Namespace) -> int:
    """`refinenet tiles run`: one job of a plan, its tile's own normals."""
    import torch

    from refinenet.atomic import atomic_group
    from refinenet.cli.jobs import Plan, job_normals
    from refinenet.data.io import read_cloud, save_record
    from refinenet.errors import InputError

    start = time.perf_counter()
    torch.set_num_threads(args.threads)
    made = Plan.read(args.plan)
    output = Path(args.output)
    _check_suffix(output, ".npz", "a piece is an .npz")
    _check_outputs(made.cloud, made.release, [output], args.force,
                   {"the plan": args.plan, "the plan's initial normals": made.initial})
    if not 0 <= args.job < made.n_jobs:
        raise InputError("--job", f"must be 0 to {made.n_jobs - 1} ({args.plan} has {made.n_jobs} jobs), got "
                                  f"{args.job}")
    device, precision = _device(args)
    release = _release(made.release, device, with_networks=made.method == "refinenet", precision=precision)
    cloud = read_cloud(made.cloud)
    made.check_cloud(cloud.points, args.plan)
    initial = _given_normals(made.initial, made.cloud, len(cloud)) if made.initial else None
    ids, result = job_normals(made, args.job, cloud.points, release, initial, device, args.threads)
    with atomic_group(_written):
        save_record(output, {"ids": ids, "normals": result}, {"plan": made.digest, "job": args.job})
    print(f"{output}: job {args.job} of {made.n_jobs}, {len(ids):,} points in {time.perf_counter() - start:.1f} s",
          file=sys.stderr)
    return 0


def merge(args: argparse.Namespace) -> int:
    """`refinenet tiles merge`: every job's normals, reconciled over the strata, oriented and written."""
    from refinenet.atomic import atomic_group
    from refinenet.cli.jobs import Plan, merged
    from refinenet.data.io import output_files, read_cloud, write_points

    start = time.perf_counter()
    made = Plan.read(args.plan)
    output = Path(args.output)
    _check_outputs(made.cloud, made.release, output_files(output), args.force,
                   {"the plan": args.plan, "the plan's initial normals": made.initial, "a piece": args.pieces})
    cloud = read_cloud(made.cloud)
    made.check_cloud(cloud.points, args.plan)
    result = _oriented(args, cloud.points, merged(made, [_piece(path, made) for path in args.pieces], cloud.points))
    with atomic_group(_written):
        write_points(output, cloud.points, result)
    print(f"{output}: {len(cloud):,} points from {len(args.pieces)} jobs ({args.orient} orientation) in "
          f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


def _piece(path: str, made):
    """The (ids, normals, path) of one job's piece of the plan `made`."""
    import numpy as np

    from refinenet.data.io import load_record
    from refinenet.errors import InputError

    arrays, meta = load_record(path, ("ids", "normals"), "piece of `refinenet tiles run`")
    ids, normals = arrays["ids"], arrays["normals"]
    if meta.get("plan") != made.digest:
        raise InputError(path, "is a piece of another cloud's plan")
    if (ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer) or normals.shape != (len(ids), 3)
            or (len(ids) and not 0 <= ids.min() <= ids.max() < made.n_points)):
        raise InputError(path, "is not a piece of `refinenet tiles run` (malformed ids or normals)")
    return ids, normals, path


def _check_suffix(path: Path, suffix: str, why: str) -> None:
    from refinenet.errors import InputError

    if path.suffix.lower() != suffix:
        raise InputError(path, f"{why}: name a {suffix} file")


def _check_estimate_options(args: argparse.Namespace) -> None:
    """The options of `_estimate_options` that argparse cannot check alone."""
    from refinenet.errors import InputError

    if args.initial and args.method != "refinenet":
        raise InputError(args.initial, f"--initial is refined by Refine-Net; it cannot be used with --method "
                                       f"{args.method}")
    if args.tile_points is not None and args.tile_points < 1:
        raise InputError("--tile-points", f"must be at least 1, got {args.tile_points}")
    if args.strata != "auto" and not (args.strata.isascii() and args.strata.isdigit() and int(args.strata) >= 1):
        raise InputError("--strata", f"must be 'auto' or a whole number of at least 1, got {args.strata!r}")


def _device(args: argparse.Namespace) -> tuple[str, str]:
    """The device and the precision the options resolve to on this machine."""
    from refinenet.errors import InputError
    from refinenet.network.devices import resolve_device, resolve_precision

    try:
        device = resolve_device(args.device)
    except ValueError as err:
        raise InputError("--device", str(err)) from None
    return str(device), resolve_precision(args.precision, device)


def _needed(args: argparse.Namespace, n_points: int, release) -> int:
    """The points the method needs (its largest neighbourhood), refused if the cloud, read before the release that
    sets them, has fewer."""
    from refinenet.cli.estimate import min_points
    from refinenet.data.io import check_count

    needed = min_points(release.params, args.method, args.initial is not None)
    check_count(args.input, n_points, needed)
    return needed


def _n_strata(args: argparse.Namespace, points, release, needed: int) -> int:
    """--strata: the rule's count for auto, else the given one if every stratum keeps `needed` points."""
    from refinenet.cli.estimate import auto_strata
    from refinenet.errors import InputError
    from refinenet.profiling import stage

    if args.strata == "auto":
        with stage("strata rule"):
            return auto_strata(points, release, args.method, args.initial is not None)
    if len(points) // int(args.strata) < needed:
        raise InputError("--strata", f"{args.strata} subsets of {len(points):,} points have fewer than the "
                                     f"{needed} points of {args.method}'s largest neighbourhood")
    return int(args.strata)


def _oriented(args: argparse.Namespace, points, normals):
    """The normals oriented as --orient asks."""
    import numpy as np

    from refinenet.geometry.orientation import orient_mst, orient_viewpoint
    from refinenet.profiling import stage

    with stage("orientation"):
        if args.orient == "mst":
            return orient_mst(points, normals)
        if args.orient == "viewpoint":
            return orient_viewpoint(points, normals, np.asarray(args.viewpoint))
        return normals


def _check_outputs(cloud: str, release: str | None, writes: list[Path], force: bool,
                   reads: dict[str, str | list[str] | None] | None = None) -> None:
    """`files.check_outputs` for a command's cloud, its release and the other files `reads` names by what they are
    (e.g. "the --initial file")."""
    from refinenet import SHIPPED
    from refinenet.cli.files import check_outputs, release_files

    named = {"the input": [cloud], "a file of the release": release_files(release or SHIPPED)}
    named |= {what: [path] if isinstance(path, str) else path for what, path in (reads or {}).items() if path}
    check_outputs(named, writes, force)


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
    _check_outputs(args.input, args.release, writes + ([Path(args.surface)] if args.surface else []), args.force,
                   {"the --normals file": args.normals})
    if Path(args.output).suffix.lower() == ".normals":
        raise OutputError(args.output, "holds normals only, and denoising moves the points (use a point format)")
    settings = replace(_release(args.release, with_networks=False).params.denoise,
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
