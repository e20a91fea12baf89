# One network per cluster (ALGORITHM.md §9). Checkpoints live outside the outputs, so a killed run resumes.


rule train:
    message:
        "train the network of cluster {wildcards.cluster}"
    input:
        code=wf.STEPS["train"].code,
        clouds=[wf.cloud_path(c) for c in TRAIN_SPECS],
        features=[wf.features_path(c) for c in TRAIN_SPECS],
        clusters=wf.CLUSTER_MODEL,
    output:
        "results/models/refinenet/cluster_{cluster}/result.json",
    wildcard_constraints:
        cluster=r"\d+",
    params:
        tracked=tracked("train"),
        network=json.dumps(P["network"]),
        patches=json.dumps(P["patches"]),
        training=lambda w: json.dumps({**P["training"], "seed": derive_seed(P["seed"], "train", w.cluster)}),
        model_dir=lambda w, output: os.path.dirname(os.path.dirname(output[0])),
        checkpoint_dir=wf.CHECKPOINT_DIR,
    log:
        "logs/train/cluster_{cluster}.log",
    benchmark:
        "logs/train/cluster_{cluster}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.train --clouds {input.clouds} --features {input.features} --clusters {input.clusters}"
        " --cluster {wildcards.cluster} --network {params.network:q} --patches {params.patches:q}"
        " --training {params.training:q} --out-dir {params.model_dir} --checkpoint-dir {params.checkpoint_dir}"
        " --threads {threads} 2>&1 | tee {log}"
