# Normal-based clustering (docs/algorithm.md §5), fitted on the training clouds only.


rule clustering:
    message:
        "cluster model (Kc = {P.clustering.n_clusters}) from the training clouds"
    input:
        code=wf.STEPS["clustering"].code,
        features=[wf.FEATURES.format(cloud=key) for key in TRAIN_KEYS],
    output:
        wf.CLUSTER_MODEL,
    params:
        tracked=tracked("clustering"),
    log:
        "logs/clustering.log",
    benchmark:
        "logs/clustering.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.clustering --features {input.features} --out {output} 2>&1 | tee {log}"
