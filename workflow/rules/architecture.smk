# [P] Table network_architecture, generated from the model definition (docs/algorithm.md §8); needs no data.


rule table_architecture:
    message:
        "table_architecture from the model definition"
    input:
        code=PIPE.steps["table_architecture"].code,
    output:
        **layout.ARCHITECTURE_FILES,
    params:
        tracked=tracked("table_architecture"),
    log:
        "logs/architecture/table_architecture.log",
    benchmark:
        "logs/architecture/table_architecture.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.architecture 2>&1 | tee {log}"
