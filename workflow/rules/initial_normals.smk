# Initial normals by multi-scale fitting patch selection (MFPS, ALGORITHM.md §2) and its simple-MFPS ablation.


rule initial_normals:
    message:
        "{wildcards.method} normals of {wildcards.split}/{wildcards.category}/{wildcards.name}"
    input:
        code=wf.STEPS["mfps"].code,
        cloud="results/clouds/{split}/{category}/{name}.npz",
    output:
        "results/normals/{method}/{split}/{category}/{name}.npy",
    wildcard_constraints:
        method="mfps|simple_mfps",
    params:
        tracked=lambda w: tracked(w.method),
        scales=" ".join(map(str, P["mfps"]["scales"])),
        mfps=P["mfps"],
        seed=lambda w: derive_seed(P["seed"], "mfps", cloud_spec(w).key),
    log:
        "logs/initial_normals/{method}/{split}/{category}/{name}.log",
    benchmark:
        "logs/initial_normals/{method}/{split}/{category}/{name}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.initial_normals --method {wildcards.method} --cloud {input.cloud}"
        " --scales {params.scales} --trials {params.mfps[trials]} --theta-t {params.mfps[theta_t]}"
        " --a-max {params.mfps[a_max]} --eta {params.mfps[eta]} --seed {params.seed} --progress --out {output}"
        " --threads {threads} 2>&1 | tee {log}"
