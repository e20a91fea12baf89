# One network per cluster (docs/algorithm.md §9). The network folder and the training history are the outputs;
# checkpoints live outside them, so a killed run resumes from its last finished epoch.


rule training:
    message:
        "train the network of cluster {wildcards.cluster}"
    input:
        code=wf.STEPS["training"].code,
        clouds=[wf.CLOUD.format(cloud=key) for key in TRAIN_KEYS],
        features=[wf.FEATURES.format(cloud=key) for key in TRAIN_KEYS],
        clusters=wf.CLUSTER_MODEL,
    output:
        network=directory(wf.NETWORK),
        history=wf.HISTORY,
    params:
        tracked=tracked("training"),
        checkpoints=wf.CHECKPOINT_DIR,
    log:
        "logs/training/cluster_{cluster}.log",
    benchmark:
        "logs/training/cluster_{cluster}.benchmark.tsv"
    threads: 1 + P.training.loader_workers  # one core trains, the others build batches
    resources:
        gpu=wf.gpus(P.training.device),
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.training --cluster {wildcards.cluster} --clouds {input.clouds} --features {input.features}"
        " --clusters {input.clusters} --out {output.network} --history {output.history}"
        " --checkpoints {params.checkpoints} --threads {threads} 2>&1 | tee {log}"
