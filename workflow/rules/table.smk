# Result tables, one step each: evaluate normals against ground truth and write CSV, booktabs LaTeX and the
# table's metrics record (docs/algorithm.md §12). The loop variable reaches the shell command as a param
# (the command is formatted when the job runs, after the loop has ended).

for name, table in catalogue.TABLES.items():

    rule:
        name:
            name
        message:
            name
        input:
            code=PIPE.steps[name].code,
            clouds=TEST_CLOUDS,
            normals=[PIPE.normals_path(m, key) for m in table.methods for key in PIPE.keys("test")],
        output:
            **catalogue.Table.files(name, table),
        params:
            tracked=tracked(name),
            table=name,
        log:
            f"logs/table/{name}.log",
        benchmark:
            f"logs/table/{name}.benchmark.tsv"
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.table --table {params.table} --clouds {input.clouds} 2>&1 | tee {log}"
