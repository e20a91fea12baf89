# [P] §Application (docs/algorithm.md §11): each test cloud with a known clean surface moved along the normals of
# PCA, MFPS and Refine-Net, and its distances to the true surface before and after; then one table of them. Only
# where the data has such clouds (procedural shapes or meshes).

if "denoise" in PIPE.steps:

    rule denoise:
        message:
            "denoise {wildcards.cloud} with the normals of each method"
        input:
            code=PIPE.steps["denoise"].code,
            cloud=layout.CLOUD,
            normals=[PIPE.normals_path(m, "{cloud}") for m in catalogue.DENOISE_METHODS],
        output:
            layout.DENOISED,
        params:
            tracked=tracked("denoise"),
        log:
            layout.fill(layout.JOB_LOG, step="denoise"),
        benchmark:
            layout.fill(layout.JOB_BENCHMARK, step="denoise"),
        threads: 1
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.denoise --output cloud --clouds {input.cloud} --normals {input.normals}"
            " --out {output} --threads {threads} 2>&1 | tee {log}"

    rule table_denoise:
        message:
            "table_denoise: distances to the true surface before and after denoising"
        input:
            code=PIPE.steps["table_denoise"].code,
            clouds=[layout.CLOUD.format(cloud=k) for k in PIPE.denoise_keys()],
            records=[layout.DENOISED.format(cloud=k) for k in PIPE.denoise_keys()],
        output:
            **catalogue.Table.files(catalogue.DENOISE_TABLE),
        params:
            tracked=tracked("table_denoise"),
        log:
            "logs/denoise/table_denoise.log",
        benchmark:
            "logs/denoise/table_denoise.benchmark.tsv"
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.denoise --output table --clouds {input.clouds} --records {input.records}"
            " 2>&1 | tee {log}"
