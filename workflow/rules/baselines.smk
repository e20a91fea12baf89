# Classical baselines of the paper's tables: PCA and Jet, K = 100 (K = 200 for BigNoise).


rule baseline_normals:
    message:
        "{wildcards.method} normals of {wildcards.split}/{wildcards.category}/{wildcards.name}"
    input:
        code=wf.STEPS["baselines"].code,
        cloud="results/clouds/{split}/{category}/{name}.npz",
    output:
        "results/normals/{method}/{split}/{category}/{name}.npy",
    wildcard_constraints:
        method="|".join(wf.BASELINES),
    params:
        tracked=tracked("baselines"),
        k=baseline_k,
        degree=P["baselines"]["jet_degree"],
    log:
        "logs/baseline_normals/{method}/{split}/{category}/{name}.log",
    benchmark:
        "logs/baseline_normals/{method}/{split}/{category}/{name}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.baseline_normals --method {wildcards.method} --cloud {input.cloud}"
        " --k {params.k} --degree {params.degree} --out {output} --threads {threads} 2>&1 | tee {log}"
