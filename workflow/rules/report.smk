# The reports in one place: reports/index.html (every table and figure, the profile and settings that made them;
# after `snakemake main`, the main job's beside the committed results of the rest: `main_page`) and
# reports/tables.tex (every table in one LaTeX document), which report_pdf compiles where pdflatex is installed.


rule report:
    message:
        "report: reports/index.html and reports/tables.tex"
    input:
        code=PIPE.steps["report"].code,
        reported=lambda wildcards: reported_files(PIPE, main_page()),
    output:
        **layout.REPORT_FILES,
    params:
        scope=lambda wildcards: "main" if main_page() else "all",
        tracked=tracked("report"),
    log:
        "logs/report/report.log",
    benchmark:
        "logs/report/report.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.report --output page --scope {params.scope} 2>&1 | tee {log}"


rule report_pdf:
    message:
        "report_pdf: reports/tables.pdf"
    input:
        code=PIPE.steps["report_pdf"].code,
        tex=layout.REPORT_FILES["tex"],
    output:
        layout.TABLES_PDF,
    params:
        tracked=tracked("report_pdf"),
    log:
        "logs/report/report_pdf.log",
    benchmark:
        "logs/report/report_pdf.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.report --output pdf 2>&1 | tee {log}"
