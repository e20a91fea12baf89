# The reports in one place: reports/index.html (every table and figure, the profile and settings that made them)
# and reports/tables.tex (every table in one LaTeX document), which report_pdf compiles where pdflatex is installed.


rule report:
    message:
        "report: reports/index.html and reports/tables.tex"
    input:
        code=PIPE.steps["report"].code,
        reported=reported_files(PIPE),
    output:
        **layout.REPORT_FILES,
    params:
        tracked=tracked("report"),
    log:
        "logs/report/report.log",
    benchmark:
        "logs/report/report.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.report --output page 2>&1 | tee {log}"


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
