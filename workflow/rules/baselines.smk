# Classical baselines of the paper's tables: PCA and Jet (K = 100; K = 200 for BigNoise), on the test clouds, and
# on the training clouds too (baselines_train) where a Refine-Net variant is trained on their normals.

for step in PIPE.family("baselines"):

    rule:
        name:
            step.name
        message:
            "{wildcards.method} normals of {wildcards.cloud}"
        input:
            code=step.code,
            cloud=layout.CLOUD,
        output:
            layout.NORMALS,
        wildcard_constraints:
            method="|".join(BASELINES),
            cloud=rf"{step.split}/[^/]+/[^/]+",
        params:
            tracked=tracked(step.name),
        log:
            "logs/baselines/{method}/{cloud}.log",
        benchmark:
            "logs/baselines/{method}/{cloud}.benchmark.tsv"
        threads: 1
        priority: split_priority(step.split)
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.baselines --method {wildcards.method} --cloud {input.cloud} --out {output}"
            " --threads {threads} 2>&1 | tee {log}"
