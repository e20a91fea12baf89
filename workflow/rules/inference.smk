# Refine-Net normals of every test cloud, merged across clusters, in the PCPNet format (ALGORITHM.md §10).


rule refine:
    message:
        "Refine-Net normals of {wildcards.split}/{wildcards.category}/{wildcards.name}"
    input:
        code=wf.STEPS["refine"].code,
        cloud="results/clouds/{split}/{category}/{name}.npz",
        features="results/features/{split}/{category}/{name}.npz",
        clusters=wf.CLUSTER_MODEL,
        trained=[wf.trained_marker(c) for c in range(P["clustering"]["n_clusters"])],
    output:
        "results/normals/refinenet/{split}/{category}/{name}.normals",
    params:
        tracked=tracked("refine"),
        network=json.dumps(P["network"]),
        patches=json.dumps(P["patches"]),
        inference=P["inference"],
        model_dir=lambda w, input: os.path.dirname(os.path.dirname(input.trained[0])),
        seed=lambda w: derive_seed(P["seed"], "refine", cloud_spec(w).key),
    log:
        "logs/refine/{split}/{category}/{name}.log",
    benchmark:
        "logs/refine/{split}/{category}/{name}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.refine --cloud {input.cloud} --features {input.features} --clusters {input.clusters}"
        " --model-dir {params.model_dir} --network {params.network:q} --patches {params.patches:q}"
        " --batch-size {params.inference[batch_size]} --device {params.inference[device]} --seed {params.seed}"
        " --out {output} --threads {threads} 2>&1 | tee {log}"
