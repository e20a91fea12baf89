# Simulated range scans (docs/algorithm.md §1.5): each shape of params.yaml `scanner.shapes` seen by a virtual depth
# camera from every viewpoint, with the exact normals of the surface points hit.


rule simulate_scans:
    message:
        "scan {wildcards.shape}"
    input:
        code=PIPE.steps["simulate_scans"].code,
    output:
        layout.SCAN,
    wildcard_constraints:
        shape=r"[a-z][a-z0-9_]*",
    params:
        tracked=tracked("simulate_scans"),
    log:
        "logs/simulate/{shape}.log",
    benchmark:
        "logs/simulate/{shape}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.simulate --shape {wildcards.shape} --out {output} --threads {threads}"
        " 2>&1 | tee {log}"
