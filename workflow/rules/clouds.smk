# Clouds, one step per split: sample each shape or mesh and add seeded Gaussian noise, or read a given cloud.

for step in PIPE.family("clouds"):

    rule:
        name:
            step.name
        message:
            "cloud {wildcards.cloud}"
        input:
            code=step.code,
        output:
            layout.CLOUD,
        wildcard_constraints:
            cloud=rf"{step.split}/[^/]+/[^/]+",
        params:
            tracked=tracked(step.name),
        log:
            "logs/clouds/{cloud}.log",
        benchmark:
            "logs/clouds/{cloud}.benchmark.tsv"
        threads: 1
        priority: split_priority(step.split)
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.clouds --cloud {wildcards.cloud} --out {output} --threads {threads} 2>&1 | tee {log}"
