"""Where the pipeline's files live, as Snakemake patterns: the rules, the step declarations, the stage scripts and
the benchmarks all find a file through these, so a path is written once. `{cloud}` is a cloud's key
`<split>/<category>/<name>`, `{variant}` a Refine-Net variant (params.yaml `variants`; `full` is the default
Refine-Net)."""

from __future__ import annotations

from refinenet.pipeline.methods import REFINENET

CLOUD = "results/clouds/{cloud}.npz"
FEATURES = "results/features/{variant}/{cloud}.npz"
NORMALS = "results/normals/{method}/{cloud}.npy"
#: Refine-Net's output is the PCPNet text format, the form users compare with other methods.
REFINED = f"results/normals/{REFINENET}/{{variant}}/{{cloud}}.normals"
CLUSTER_MODEL = "results/clusters/{variant}/model.npz"
MODEL_DIR = "results/models/{variant}"
NETWORK = f"{MODEL_DIR}/cluster_{{cluster}}"
HISTORY_DIR = "results/history/{variant}"
HISTORY = f"{HISTORY_DIR}/cluster_{{cluster}}.csv"
#: Resumable training state, outside every step's outputs so that neither tool clears it before a rerun.
CHECKPOINT_DIR = "results/checkpoints/{variant}"
#: The run's release, which `refinenet normals --release` loads. The package's own (`refinenet.SHIPPED`) is a copy
#: of one profile's (README, "The networks"), so that no run replaces the networks a clone was given.
RELEASE = "results/release"
#: Each per-cloud job's log and Snakemake benchmark file (wall seconds, peak memory), by step: a method
#: (`mfps`) or a per-variant family and its variant (`features/full`).
JOB_LOG = "logs/{step}/{cloud}.log"
JOB_BENCHMARK = "logs/{step}/{cloud}.benchmark.tsv"
#: A simulated range scan of one procedural shape (`data.scans`): its points and exact normals, as a user's scan.
SCANS_DIR = "results/scans"
SCAN = f"{SCANS_DIR}/{{shape}}.ply"
#: The denoising application's record of one test cloud: its denoised points and distances to the true surface.
DENOISED = "results/denoised/{cloud}.npz"

#: A table's files (`catalogue.Table.files`); the line plot is a sweep table's only (e.g. the Kc sweep).
TABLE_FILES = {"csv": "reports/{table}.csv", "tex": "reports/{table}.tex", "per_cloud": "reports/per_cloud/{table}.csv"}
TABLE_METRICS = "reports/metrics/{table}.json"
TABLE_PLOT = "reports/{table}.png"
#: [P] Table time, from the job benchmark files (`pipeline.timing`): it differs from run to run.
TIME_FILES = {"csv": "reports/table_time.csv", "tex": "reports/table_time.tex",
              "per_cloud": "reports/per_cloud/table_time.csv", "metrics": "reports/metrics/table_time.json"}
ARCHITECTURE_FILES = {"csv": "reports/table_architecture.csv", "tex": "reports/table_architecture.tex",
                      "layers": "reports/table_architecture_layers.csv"}
COMPARISON_FILES = {"md": "reports/paper_comparison.md", "tex": "reports/paper_comparison.tex"}

#: The figures, each in every format it is written in (the methods, clouds and variants each shows: `catalogue`).
#: [P] fig:syn and fig:insight: normals as RGB and error heat maps of chosen test clouds (`evaluation.figures`).
FIGURE_NORMALS = {"png": "reports/figures/normals_and_errors.png", "pdf": "reports/figures/normals_and_errors.pdf"}
#: [P] fig:cluster: a test cloud coloured by cluster for two Kc, beside the Kc curve of table_clusters.
FIGURE_CLUSTERS = {"png": "reports/figures/clusters.png", "pdf": "reports/figures/clusters.pdf"}
#: [P] fig:loss2: one shape at increasing noise, each point blue where L1 (variant l1) gives the lower error and red
#: where L2 (variant l2, mse) does.
FIGURE_LOSS = {"png": "reports/figures/l1_against_l2.png", "pdf": "reports/figures/l1_against_l2.pdf"}
#: Training loss and validation error per epoch of every cluster, one figure per trained variant.
FIGURE_TRAINING_DIR = "reports/figures/training"
FIGURE_TRAINING = f"{FIGURE_TRAINING_DIR}/{{variant}}.png"
#: [P] fig:real_boy and fig:outdoor: normals as RGB on scans (simulated, or a folder of real ones).
FIGURE_REAL = {"png": "reports/figures/real_scans.png", "pdf": "reports/figures/real_scans.pdf"}
#: [P] fig:block: a test cloud denoised with each method's normals.
FIGURE_DENOISE = {"png": "reports/figures/denoising.png", "pdf": "reports/figures/denoising.pdf"}

#: The page with every table and figure (`evaluation.report`), and one LaTeX document of every table; report_pdf
#: compiles that document where pdflatex is installed.
REPORT_FILES = {"html": "reports/index.html", "tex": "reports/tables.tex"}
TABLES_PDF = "reports/tables.pdf"
REPORT_DIR = "reports"
#: Files that hold the timings of the run that made them (table_time and the reports that include it): they differ
#: from run to run.
TIMED_FILES = (*TIME_FILES.values(), *REPORT_FILES.values(), TABLES_PDF)


def fill(pattern: str, **values: object) -> str:
    """`pattern` with the given wildcards filled in and the others left as Snakemake wildcards."""
    class Keep(dict):
        def __missing__(self, key: str) -> str:
            return f"{{{key}}}"
    return pattern.format_map(Keep(values))
