# [P] fig:syn / fig:insight: normals as RGB and angular-error heat maps of chosen test clouds, one column per
# method and variant of params.yaml `figures.variants` (docs/algorithm.md §12, Figures).


rule fig_normals:
    message:
        "fig_normals: normals and error maps"
    input:
        code=PIPE.steps["fig_normals"].code,
        clouds=[layout.CLOUD.format(cloud=key) for key in PIPE.figure_keys()],
        normals=[PIPE.normals_path(m, key) for m in PIPE.figure_methods() for key in PIPE.figure_keys()],
    output:
        **layout.FIGURE_NORMALS,
    params:
        tracked=tracked("fig_normals"),
    log:
        "logs/fig/fig_normals.log",
    benchmark:
        "logs/fig/fig_normals.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.fig --figure normals --clouds {input.clouds} 2>&1 | tee {log}"


# [P] fig:cluster: points coloured by cluster for Kc = 2 and Kc = 4, beside the Kc curve of table_clusters.


rule fig_clusters:
    message:
        "fig_clusters: clusters and the Kc curve"
    input:
        code=PIPE.steps["fig_clusters"].code,
        cloud=layout.CLOUD.format(cloud=PIPE.figure_keys()[0]),
        features=files(FULL, "features", layout.FEATURES, cloud=PIPE.figure_keys()[0]),
        clusters=[files(v, "clustering", layout.CLUSTER_MODEL) for v in catalogue.CLUSTER_FIGURE_VARIANTS],
        sweep=catalogue.Table.files("table_clusters")["csv"],
    output:
        **layout.FIGURE_CLUSTERS,
    params:
        tracked=tracked("fig_clusters"),
    log:
        "logs/fig/fig_clusters.log",
    benchmark:
        "logs/fig/fig_clusters.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.fig --figure clusters --clouds {input.cloud} --features {input.features}"
        " --clusters {input.clusters} --sweep {input.sweep} 2>&1 | tee {log}"


# [P] fig:loss2: one test shape at increasing noise, each point blue where L1 gives the lower error, red where L2 does.


rule fig_loss:
    message:
        "fig_loss: L1 against L2 per point"
    input:
        code=PIPE.steps["fig_loss"].code,
        clouds=[layout.CLOUD.format(cloud=key) for key in PIPE.loss_figure_keys()],
        normals=[
            PIPE.normals_path(m, key)
            for m in catalogue.TABLES["table_loss"].methods
            for key in PIPE.loss_figure_keys()
        ],
    output:
        **layout.FIGURE_LOSS,
    params:
        tracked=tracked("fig_loss"),
    log:
        "logs/fig/fig_loss.log",
    benchmark:
        "logs/fig/fig_loss.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.fig --figure loss --clouds {input.clouds} 2>&1 | tee {log}"


# Training loss and validation error per epoch of every cluster, one figure per trained variant.


rule fig_training:
    message:
        "fig_training: training curves of variant {wildcards.variant}"
    input:
        code=PIPE.steps["fig_training"].code,
        histories=lambda wildcards: [
            layout.HISTORY.format(variant=wildcards.variant, cluster=c)
            for c in range(PIPE.params[wildcards.variant].clustering.n_clusters)
        ],
    output:
        layout.FIGURE_TRAINING,
    wildcard_constraints:
        variant="|".join(PIPE.trained),
    params:
        tracked=tracked("fig_training"),
    log:
        "logs/fig/fig_training_{variant}.log",
    benchmark:
        "logs/fig/fig_training_{variant}.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.fig --figure training --variant {wildcards.variant} 2>&1 | tee {log}"


# [P] fig:real_boy / fig:outdoor: normals as RGB on scans by PCA, Jet, MFPS and Refine-Net with X = 8, the paper's
# real-data setting: a folder of real scans where params.yaml `figures.scans` names one, else the simulated scans.

rule fig_real:
    message:
        "fig_real: normals on the scans"
    input:
        code=PIPE.steps["fig_real"].code,
        scans=P.figures.scans or [layout.SCAN.format(shape=s) for s in PIPE.scanner.shapes],
        clouds=[layout.CLOUD.format(cloud=key) for key in TRAIN_KEYS],
        clusters=files(catalogue.REAL_VARIANT, "clustering", layout.CLUSTER_MODEL),
        networks=networks(catalogue.REAL_VARIANT),
    output:
        **layout.FIGURE_REAL,
    params:
        tracked=tracked("fig_real"),
    log:
        "logs/fig/fig_real.log",
    benchmark:
        "logs/fig/fig_real.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.fig --figure real --scans {input.scans} --clouds {input.clouds}"
        " --clusters {input.clusters} --networks {input.networks} 2>&1 | tee {log}"


# [P] fig:block: one test cloud denoised with each method's normals, its points and screened Poisson surfaces.

if "fig_denoise" in PIPE.steps:

    rule fig_denoise:
        message:
            "fig_denoise: denoised points and surfaces"
        input:
            code=PIPE.steps["fig_denoise"].code,
            cloud=layout.CLOUD.format(cloud=PIPE.denoise_figure_key()),
            record=layout.DENOISED.format(cloud=PIPE.denoise_figure_key()),
        output:
            **layout.FIGURE_DENOISE,
        params:
            tracked=tracked("fig_denoise"),
        log:
            "logs/fig/fig_denoise.log",
        benchmark:
            "logs/fig/fig_denoise.benchmark.tsv"
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.fig --figure denoise --clouds {input.cloud} --records {input.record} 2>&1 | tee {log}"
