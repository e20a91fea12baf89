# The normals of one large cloud as Snakemake jobs, one per tile, with the normals of `refinenet normals`:
#   snakemake -s workflow/tiles.smk -j2 --config input=scan.ply output=scan_normals.ply
#   snakemake -s workflow/tiles.smk --profile workflow/profiles/slurm --config input=scan.ply output=scan_normals.ply
# More keys (--config KEY=VALUE): tile_points (own points per tile, default 500000), strata (auto or S), method,
# scale, release, initial, orient, viewpoint ("X Y Z"), precision, threads (per tile job, default 2), and work (the
# folder of the plan and the pieces, default OUTPUT.tiles; emptied once the output is written). The memory each job
# asks a cluster for is an estimate from the cloud's size and tile_points (a tile of 500k own points peaks at
# about 2.5 GB beside the cloud, which every job reads); --set-resources overrides it.

import json
import os

INPUT = config["input"]
OUTPUT = config["output"]
WORK = config.get("work", f"{OUTPUT}.tiles")
TILE_POINTS = int(config.get("tile_points", 500_000))
THREADS = int(config.get("threads", 2))


def options(*keys):
    """The command-line options of the `config` keys given, for the keys that are set."""
    return " ".join(f"--{key.replace('_', '-')} {config[key]}" for key in keys if key in config)


#: Memory estimates: the interpreter and the networks (MB), then kB per point of the cloud (the plan's neighbour
#: lists; a job's copies of the cloud; the merge's consensus and orientation) and per own point of a tile.
BASE_MB, PLAN_KB, JOB_KB, MERGE_KB, TILE_KB = 1000, 0.2, 0.1, 0.3, 5


def planned_points(input):
    """The points of the cloud, from the plan (the first input of the rules after it)."""
    with open(input[0]) as fh:
        return json.load(fh)["n_points"]


def plan_mb(wildcards, input):
    """Before the plan, the points are bounded by the file's size (at least 12 bytes a point)."""
    return int(BASE_MB + PLAN_KB * os.path.getsize(input[0]) / 12 / 1000)


def tile_mb(wildcards, input):
    return int(BASE_MB + (JOB_KB * planned_points(input) + TILE_KB * TILE_POINTS) / 1000)


def merge_mb(wildcards, input):
    return int(BASE_MB + MERGE_KB * planned_points(input) / 1000)


checkpoint plan:
    input:
        INPUT,
    output:
        temp(f"{WORK}/plan.json"),
    threads: THREADS
    resources:
        mem_mb=plan_mb,
    shell:
        "refinenet tiles plan {input} -o {output} --tile-points {TILE_POINTS} --threads {threads} "
        + options("strata", "method", "scale", "release", "initial")


rule tile:
    input:
        f"{WORK}/plan.json",
    output:
        temp(f"{WORK}/{{job}}.npz"),
    threads: THREADS
    resources:
        mem_mb=tile_mb,
    shell:
        "refinenet tiles run {input} --job {wildcards.job} -o {output} --threads {threads} " + options("precision")


def pieces(wildcards):
    """Every job's piece, once the plan says how many jobs there are."""
    with open(checkpoints.plan.get().output[0]) as fh:
        n_jobs = sum(json.load(fh)["n_tiles"])
    return [f"{WORK}/{job}.npz" for job in range(n_jobs)]


rule merge:
    default_target: True
    input:
        plan=f"{WORK}/plan.json",
        pieces=pieces,
    output:
        OUTPUT,
    threads: THREADS
    resources:
        mem_mb=merge_mb,
    shell:
        "refinenet tiles merge {input.plan} {input.pieces} -o {output} --threads {threads} "
        + options("orient", "viewpoint")
