# Result tables: evaluate normals against ground truth and write CSV, booktabs LaTeX and per-table metrics;
# then merge the metrics into reports/metrics.json for `dvc metrics`.


rule table:
    message:
        "{wildcards.table}"
    input:
        code=lambda w: wf.STEPS[w.table].code,
        clouds=TEST_CLOUDS,
        normals=lambda w: [wf.normals_path(m, c) for m in wf.TABLES[w.table].methods for c in TEST_SPECS],
    output:
        csv="reports/{table}.csv",
        tex="reports/{table}.tex",
        per_cloud="reports/per_cloud/{table}.csv",
        metrics="reports/metrics/{table}.json",
    wildcard_constraints:
        table="|".join(wf.TABLES),
    params:
        tracked=lambda w: tracked(w.table),
        protocol=P["evaluation"]["protocol"],
        methods=lambda w: " ".join(wf.TABLES[w.table].methods),
        metrics=lambda w: " ".join(wf.TABLES[w.table].metrics),
        caption=lambda w: caption(wf.TABLES[w.table].title, P, wf.TABLES[w.table].methods),
    log:
        "logs/table/{table}.log",
    benchmark:
        "logs/table/{table}.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.table --methods {params.methods} --clouds {input.clouds} --normals {input.normals}"
        " --protocol {params.protocol} --metrics {params.metrics} --caption {params.caption:q}"
        " --label {wildcards.table} --csv {output.csv} --tex {output.tex} --per-cloud {output.per_cloud}"
        " --metrics-json {output.metrics} 2>&1 | tee {log}"


rule metrics:
    message:
        "reports/metrics.json from every table"
    input:
        code=wf.STEPS["metrics"].code,
        tables=[t.metrics_file(n) for n, t in wf.TABLES.items()],
    output:
        "reports/metrics.json",
    params:
        tracked=tracked("metrics"),
    log:
        "logs/metrics.log",
    benchmark:
        "logs/metrics.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.merge_metrics --inputs {input.tables} --out {output} 2>&1 | tee {log}"
