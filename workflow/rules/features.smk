# Feature cache per cloud: multi-scale filtered normals, per-point frames, height maps (docs/algorithm.md §3, §4, §7).


rule features:
    message:
        "features of {wildcards.cloud}"
    input:
        code=wf.STEPS["features"].code,
        cloud=wf.CLOUD,
        initial=wf.normals_path("mfps", "{cloud}"),
    output:
        wf.FEATURES,
    params:
        tracked=tracked("features"),
    log:
        "logs/features/{cloud}.log",
    benchmark:
        "logs/features/{cloud}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.features --cloud {input.cloud} --initial {input.initial} --out {output}"
        " --threads {threads} 2>&1 | tee {log}"
