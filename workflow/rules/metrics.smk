# reports/metrics.json: every table's metrics in one file, for `dvc metrics show` and `dvc metrics diff`.


rule metrics:
    message:
        "reports/metrics.json from every table"
    input:
        code=wf.STEPS["metrics"].code,
        tables=[wf.Table.files(name)["metrics"] for name in wf.TABLES],
    output:
        wf.METRICS,
    params:
        tracked=tracked("metrics"),
    log:
        "logs/metrics.log",
    benchmark:
        "logs/metrics.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.metrics --inputs {input.tables} --out {output} 2>&1 | tee {log}"
