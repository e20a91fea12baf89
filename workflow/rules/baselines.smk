# Classical baselines of the paper's tables: PCA and Jet (K = 100; K = 200 for BigNoise).


rule baselines:
    message:
        "{wildcards.method} normals of {wildcards.cloud}"
    input:
        code=PIPE.steps["baselines"].code,
        cloud=wf.CLOUD,
    output:
        wf.NORMALS,
    wildcard_constraints:
        method="|".join(wf.BASELINES),
    params:
        tracked=tracked("baselines"),
    log:
        "logs/baselines/{method}/{cloud}.log",
    benchmark:
        "logs/baselines/{method}/{cloud}.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.baselines --method {wildcards.method} --cloud {input.cloud} --out {output}"
        " --threads {threads} 2>&1 | tee {log}"
