# Feature cache per cloud: multi-scale filtered normals, per-point frames, height maps (ALGORITHM.md §3, §4, §7).


rule features:
    message:
        "features of {wildcards.split}/{wildcards.category}/{wildcards.name}"
    input:
        code=wf.STEPS["features"].code,
        cloud="results/clouds/{split}/{category}/{name}.npz",
        initial="results/normals/mfps/{split}/{category}/{name}.npy",
    output:
        "results/features/{split}/{category}/{name}.npz",
    params:
        tracked=tracked("features"),
        config=json.dumps(P["features"]),
    log:
        "logs/features/{split}/{category}/{name}.log",
    benchmark:
        "logs/features/{split}/{category}/{name}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.features --cloud {input.cloud} --initial {input.initial} --config {params.config:q}"
        " --progress --out {output} --threads {threads} 2>&1 | tee {log}"
