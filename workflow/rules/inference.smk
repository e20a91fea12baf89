# Refine-Net normals of every test cloud, merged across clusters, in the PCPNet format (docs/algorithm.md §10).


rule inference:
    message:
        "Refine-Net normals of {wildcards.cloud}"
    input:
        code=wf.STEPS["inference"].code,
        cloud=wf.CLOUD,
        features=wf.FEATURES,
        clusters=wf.CLUSTER_MODEL,
        networks=[wf.NETWORK.format(cluster=c) for c in CLUSTERS],
    output:
        wf.REFINED,
    params:
        tracked=tracked("inference"),
    log:
        "logs/inference/{cloud}.log",
    benchmark:
        "logs/inference/{cloud}.benchmark.tsv"
    threads: 1
    resources:
        gpu=wf.gpus(P.inference.device),
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.inference --cloud {input.cloud} --features {input.features} --clusters {input.clusters}"
        " --networks {input.networks} --out {output} --threads {threads} 2>&1 | tee {log}"
