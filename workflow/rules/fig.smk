# [P] fig:syn / fig:insight: normals as RGB and angular-error heat maps of chosen test clouds, one column per
# method (docs/algorithm.md §12, Figures).


rule fig_normals:
    message:
        "fig_normals: normals and error maps"
    input:
        code=PIPE.steps["fig_normals"].code,
        clouds=[wf.CLOUD.format(cloud=key) for key in PIPE.figure_keys()],
        normals=[PIPE.normals_path(m, key) for m in wf.FIGURE_METHODS for key in PIPE.figure_keys()],
    output:
        **wf.FIGURE_NORMALS,
    params:
        tracked=tracked("fig_normals"),
    log:
        "logs/fig/fig_normals.log",
    benchmark:
        "logs/fig/fig_normals.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.fig --clouds {input.clouds} 2>&1 | tee {log}"
