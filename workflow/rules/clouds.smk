# Clouds, one step per split: sample each shape or mesh and add seeded Gaussian noise, or read a given cloud.

for split in ("train", "test"):

    rule:
        name:
            f"clouds_{split}"
        message:
            "cloud {wildcards.cloud}"
        input:
            code=PIPE.steps[f"clouds_{split}"].code,
        output:
            wf.CLOUD,
        wildcard_constraints:
            cloud=f"{split}/[^/]+/[^/]+",
        params:
            tracked=tracked(f"clouds_{split}"),
        log:
            "logs/clouds/{cloud}.log",
        benchmark:
            "logs/clouds/{cloud}.benchmark.tsv"
        threads: 1
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.clouds --cloud {wildcards.cloud} --out {output} --threads {threads} 2>&1 | tee {log}"
