# table_scans: the error of PCA, Jet, MFPS and Refine-Net (X = 9 and X = 8) on the simulated scans, through the chain
# of `refinenet normals`: the quantitative form of [P] table:Kinect_results.


rule table_scans:
    message:
        "table_scans: the estimators on the simulated scans"
    input:
        code=PIPE.steps["table_scans"].code,
        scans=[layout.SCAN.format(shape=s) for s in PIPE.scanner.shapes],
        release=layout.RELEASE,
        clouds=[layout.CLOUD.format(cloud=key) for key in TRAIN_KEYS],
        clusters=files(catalogue.REAL_VARIANT, "clustering", layout.CLUSTER_MODEL),
        networks=networks(catalogue.REAL_VARIANT),
    output:
        **catalogue.Table.files(catalogue.SCAN_TABLE),
    params:
        tracked=tracked("table_scans"),
    log:
        "logs/scans/table_scans.log",
    benchmark:
        "logs/scans/table_scans.benchmark.tsv"
    threads: 1
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.scans --scans {input.scans} --release {input.release} --clouds {input.clouds}"
        " --clusters {input.clusters} --networks {input.networks} --threads {threads} 2>&1 | tee {log}"
