# Clouds: sample each shape or mesh and add seeded Gaussian noise, or read a given cloud.


rule cloud:
    message:
        "cloud {wildcards.split}/{wildcards.category}/{wildcards.name}"
    input:
        code=wf.STEPS["test_clouds"].code,
    output:
        "results/clouds/{split}/{category}/{name}.npz",
    params:
        tracked=lambda w: tracked(f"{w.split}_clouds"),
        origin=lambda w: cloud_spec(w).origin,
        noise=lambda w: "" if cloud_spec(w).noise is None else f"--noise {cloud_spec(w).noise}",
        n_points=P["data"]["n_points"],
        seed=P["seed"],
    log:
        "logs/cloud/{split}/{category}/{name}.log",
    benchmark:
        "logs/cloud/{split}/{category}/{name}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.cloud --split {wildcards.split} --category {wildcards.category}"
        " --name {wildcards.name} --origin {params.origin:q} {params.noise} --n-points {params.n_points}"
        " --seed {params.seed} --out {output} --threads {threads} 2>&1 | tee {log}"
