"""What the paper's tables and figures show, as data: each table's rows (methods, Refine-Net variants among them)
and columns (metrics), each figure's methods, clouds and variants, and the main job. A table is one entry of
TABLES: its rule, step, report entry and caption follow from it."""

from __future__ import annotations

from dataclasses import dataclass

from refinenet.evaluation.table import METHOD_NAMES
from refinenet.pipeline.layout import TABLE_FILES, TABLE_METRICS, TABLE_PLOT
from refinenet.pipeline.methods import BASELINES, FULL, MFPS_METHODS, REFERENCE, REFINENET, refinenet, variant_of


@dataclass(frozen=True)
class Table:
    """A results table of the paper: which methods are its rows and which metrics its columns."""

    methods: tuple[str, ...]
    metrics: tuple[str, ...]
    title: str
    labels: tuple[tuple[str, str], ...] = ()
    """Row names of this table where they differ from the methods' usual names (e.g. full as Refine-Net-Weight)."""
    sweep: tuple[str, str] | None = None
    """(params key, symbol): the rows are variants that differ in this key; each is labelled and ordered by its
    value (the first of equal values kept), and the Average mean error is plotted against it."""
    protocol: str | None = None
    """How categories aggregate (`evaluation.protocol`'s values): fixed by the table, or None for the run's."""

    @staticmethod
    def files(name: str, table: Table | None = None) -> dict[str, str]:
        """The table's outputs by kind: csv, tex, per_cloud, its metrics record and, for a sweep, the plot."""
        files = {**{kind: path.format(table=name) for kind, path in TABLE_FILES.items()},
                 "metrics": TABLE_METRICS.format(table=name)}
        if table is not None and table.sweep:
            files["plot"] = TABLE_PLOT.format(table=name)
        return files

    @property
    def variants(self) -> list[str]:
        return [v for v in map(variant_of, self.methods) if v is not None]


_SYNTHETIC = (*BASELINES, *MFPS_METHODS, REFINENET)
#: Rows of the ablation table ([P] table:ablation_results), after MFPS and simple MFPS.
ABLATION = (("normals", "normals"), ("normals_hmps", "normals&HMPs"), ("normals_points", "normals&points"),
            ("concat", "concat"), ("residual", "residual"), ("rot", "Refine-Net-Rot"), ("trans", "Refine-Net-Trans"),
            (REFERENCE, "Refine-Net-Weight"))
TABLES = {
    "table_baselines": Table(BASELINES, ("mean", "rmse"), "Baselines: unoriented angular error (degrees)"),
    "table_synthetic": Table(_SYNTHETIC, ("mean", "rmse"), "Synthetic benchmark: unoriented angular error (degrees)"),
    "table_synthetic_pgp": Table(_SYNTHETIC, ("pgp5", "pgp10"),
                                 "Synthetic benchmark: proportion of good points (error below 5 and 10 degrees)"),
    "table_ablation": Table((*MFPS_METHODS, *(refinenet(v) for v, _ in ABLATION)), ("mean", "rmse"),
                            "Ablation study: unoriented angular error (degrees)",
                            labels=tuple((refinenet(v), label) for v, label in ABLATION)),
    "table_loss": Table((refinenet("l1"), refinenet("l2")), ("mean", "rmse"),
                        "Training loss, L1 against L2: unoriented angular error (degrees)",
                        labels=((refinenet("l1"), "L1"), (refinenet("l2"), "L2"))),
    "table_initial": Table(("pca", refinenet("pca_init"), "jet", refinenet("jet_init"), "mfps", refinenet(REFERENCE),
                            refinenet("pca_input")),
                           ("mean", "rmse", "pgp10"),
                           "Refine-Net on other initial normals: unoriented angular error (degrees) and PGP10",
                           labels=((refinenet("pca_init"), "PCA + Refine-Net"),
                                   (refinenet("jet_init"), "Jet + Refine-Net"),
                                   (refinenet(REFERENCE), "MFPS + Refine-Net"),
                                   (refinenet("pca_input"), "MFPS + Refine-Net (PCA K = 100 input)"))),
    "table_pcpnet": Table((*BASELINES, *MFPS_METHODS[:1], REFINENET), ("rmse",),
                          "PCPNet benchmark: RMSE (degrees) on each shape's scored points (its .pidx subset), "
                          "averaged over the shapes of a column",
                          protocol="pcpnet"),
    "table_clusters": Table(tuple(refinenet(v) for v in (REFERENCE, "kc1", "kc2", "kc3", "kc5", "kc6", "kc8")),
                            ("mean", "rmse"), "Number of clusters Kc: unoriented angular error (degrees)",
                            sweep=("clustering.n_clusters", "Kc")),
    "table_seeds": Table(tuple(refinenet(v) for v in (REFERENCE, "seed2023", "seed2024")), ("mean", "rmse"),
                         "Refine-Net under three seeds of its clustering, training and inference: unoriented angular "
                         "error (degrees)", sweep=("seed", "seed")),
}

#: [P] Table network_architecture: the networks whose height-map modules it shows, with their column titles.
ARCHITECTURE = {FULL: "Refine-Net", "normals_hmps": "Ablation (normals&HMPs)"}

#: The estimators the normals figure compares, one column each: PCA, Jet, MFPS and Refine-Net ([P] fig:syn and
#: fig:insight), then the variants of params.yaml `figures.variants`.
FIGURE_METHODS = (*BASELINES, "mfps", REFINENET)
#: The categories of the normals figure's clouds, as in fig:syn: a CAD shape with sharp edges and one with rich detail.
FIGURE_CATEGORIES = ("SharpFeature", "RichFeature")
#: [P] fig:cluster: the first figure cloud coloured by cluster for Kc = 2 (variant kc2) and Kc = 4 (full), beside
#: the Kc curve of table_clusters.
CLUSTER_FIGURE_VARIANTS = ("kc2", FULL)
#: The paper's real-data setting (X = 8: no initial normal among the inputs), this variant: fig_real and table_scans
#: run it on scans through the chain of `refinenet normals` (radii from the point spacing, `cli.estimate`).
REAL_VARIANT = "x8"
#: The simulated range scans (params.yaml `scanner`, docs/algorithm.md §1.5) have exact normals: this table scores on
#: them PCA, Jet, MFPS and Refine-Net, the release and REAL_VARIANT (the paper's real-data setting), through the chain
#: of `refinenet normals`, as [P] table:Kinect_results does on real Kinect v1 scans.
SCAN_TABLE = "table_scans"
SCAN_METHODS = (*BASELINES, "mfps", REFINENET, refinenet(REAL_VARIANT))
#: [P] fig:real_boy and fig:outdoor (fig_real): the scan table's methods but the release, Refine-Net in the real-data
#: setting alone as [P] shows it, on the simulated scans or on the real ones of params.yaml `figures.scans`.
SCAN_FIGURE_METHODS = tuple(m for m in SCAN_METHODS if m != REFINENET)

#: [P] §Application (docs/algorithm.md §11): every test cloud with a known clean surface denoised with the normals of
#: each method, a record of its points and distances to the true surface per cloud, a table of the distances and a
#: figure of the denoised points and surfaces.
DENOISE_METHODS = ("pca", "mfps", REFINENET)
DENOISE_INPUT = "input"
DENOISE_NAMES = {DENOISE_INPUT: "noisy input", **METHOD_NAMES}
DENOISE_TABLE = "table_denoise"

#: The tables `paper_comparison` sets beside the paper's numbers, in its order.
COMPARED_TABLES = (*TABLES, SCAN_TABLE)

#: The main job's steps (`snakemake main`, scripts/run.sh; `dvc repro` of them): the synthetic benchmark's tables, the
#: shipped release and the normals figure, within the default profile's budget. `snakemake main` also draws the
#: release's training curves and builds the page of them (`Pipeline.main_targets`). The ablation tables, each
#: trained variant by variant, are built by the full run.
MAIN = ("table_baselines", "table_synthetic", "table_synthetic_pgp", "release", "fig_normals")
