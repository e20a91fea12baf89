# One network per cluster (docs/algorithm.md §9), one step per variant. The network folder and the training
# history are the outputs; checkpoints live outside them, so a killed run resumes from its last finished epoch.
# Training is the longest step on the way to the tables: its jobs go before others that are ready, largest
# cluster (cluster 0, `clustering.fit_clusters`) first, so that the longest job does not start last.

for step in PIPE.family("training"):

    rule:
        name:
            step.name
        message:
            f"train the network of cluster {{wildcards.cluster}} ({step.variant})"
        input:
            code=step.code,
            clouds=[layout.CLOUD.format(cloud=key) for key in TRAIN_KEYS],
            features=[files(step.variant, "features", layout.FEATURES, cloud=key) for key in TRAIN_KEYS],
            clusters=files(step.variant, "clustering", layout.CLUSTER_MODEL),
        output:
            network=directory(layout.fill(layout.NETWORK, variant=step.variant)),
            history=layout.fill(layout.HISTORY, variant=step.variant),
        params:
            tracked=tracked(step.name),
            variant=step.variant,
            checkpoints=layout.CHECKPOINT_DIR.format(variant=step.variant),
        log:
            f"logs/training/{step.variant}/cluster_{{cluster}}.log",
        benchmark:
            f"logs/training/{step.variant}/cluster_{{cluster}}.benchmark.tsv"
        threads: 1 + PIPE.params[step.variant].training.loader_workers  # one core trains, the others build batches
        priority:  # bound per variant: a bare `step` would be the loop's last when Snakemake calls it
            lambda wildcards, kc=PIPE.params[step.variant].clustering.n_clusters: 1 + kc - int(wildcards.cluster)
        resources:
            gpu=gpus(PIPE.params[step.variant].training.device),
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.training --variant {params.variant} --cluster {wildcards.cluster}"
            " --clouds {input.clouds} --features {input.features} --clusters {input.clusters}"
            " --out {output.network} --history {output.history} --checkpoints {params.checkpoints}"
            " --threads {threads} 2>&1 | tee {log}"
