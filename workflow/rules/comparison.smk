# reports/paper_comparison.md and .tex: our tables beside the paper's published numbers, with its claimed orderings.


rule paper_comparison:
    message:
        "our tables beside the paper's numbers"
    input:
        code=PIPE.steps["paper_comparison"].code,
        tables=[catalogue.Table.files(name)["csv"] for name in catalogue.COMPARED_TABLES],
    output:
        **layout.COMPARISON_FILES,
    params:
        tracked=tracked("paper_comparison"),
    log:
        "logs/comparison/paper_comparison.log",
    benchmark:
        "logs/comparison/paper_comparison.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.comparison --tables {input.tables} 2>&1 | tee {log}"
