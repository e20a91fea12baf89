# Normal-based clustering (ALGORITHM.md §5), fitted on the training clouds only.


rule clusters:
    message:
        "cluster model (Kc = {params.n_clusters}) from the training clouds"
    input:
        code=wf.STEPS["clusters"].code,
        features=[wf.features_path(c) for c in TRAIN_SPECS],
    output:
        wf.CLUSTER_MODEL,
    params:
        tracked=tracked("clusters"),
        n_clusters=P["clustering"]["n_clusters"],
        restarts=P["clustering"]["restarts"],
        max_samples=P["clustering"]["max_samples"],
        seed=derive_seed(P["seed"], "clusters"),
    log:
        "logs/clusters.log",
    benchmark:
        "logs/clusters.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.clusters --features {input.features} --n-clusters {params.n_clusters}"
        " --restarts {params.restarts} --max-samples {params.max_samples} --seed {params.seed}"
        " --out {output} 2>&1 | tee {log}"
