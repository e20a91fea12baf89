# Result tables: evaluate normals against ground truth and write CSV, booktabs LaTeX and metrics.json.


rule table_baselines:
    message:
        "table of the PCA and Jet baselines"
    input:
        code=wf.STEPS["table_baselines"].code,
        clouds=TEST_CLOUDS,
        normals=[wf.normals_path(m, c) for m in wf.BASELINES for c in CLOUDS.values() if c.split == "test"],
    output:
        csv="reports/table_baselines.csv",
        tex="reports/table_baselines.tex",
        per_cloud="reports/per_cloud_baselines.csv",
        metrics="reports/metrics.json",
    params:
        tracked=tracked("table_baselines"),
        protocol=P["evaluation"]["protocol"],
        caption=table_caption(),
        methods=" ".join(wf.BASELINES),
    log:
        "logs/table_baselines.log",
    benchmark:
        "logs/table_baselines.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.table --methods {params.methods} --clouds {input.clouds} --normals {input.normals}"
        " --protocol {params.protocol} --metrics mean rmse --caption {params.caption:q} --label table_baselines"
        " --csv {output.csv} --tex {output.tex} --per-cloud {output.per_cloud} --metrics-json {output.metrics}"
        " 2>&1 | tee {log}"
