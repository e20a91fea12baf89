# The run's release (results/release): the trained networks, the cluster model and the run's settings in one file
# that `refinenet normals --release` loads without training, with a model card. The shipped networks are a copy of
# one profile's (README, "The networks").


rule release:
    message:
        "export the trained networks as the release of profile {P.profile}"
    input:
        code=PIPE.steps["release"].code,
        clouds=[layout.CLOUD.format(cloud=key) for key in TRAIN_KEYS],
        clusters=layout.CLUSTER_MODEL.format(variant=FULL),
        networks=networks(FULL),
        check_clouds=[layout.CLOUD.format(cloud=key) for key in check_keys(P)],
        check_features=[layout.FEATURES.format(variant=FULL, cloud=key) for key in check_keys(P)],
    output:
        directory(layout.RELEASE),
    params:
        tracked=tracked("release"),
    log:
        "logs/release.log",
    benchmark:
        "logs/release.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.release --clouds {input.clouds} --clusters {input.clusters} --networks {input.networks}"
        " --check-clouds {input.check_clouds} --check-features {input.check_features} --out {output}"
        " 2>&1 | tee {log}"
