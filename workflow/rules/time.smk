# [P] Table time from the job benchmark files of full's MFPS, features and inference, and the model definition.
# Its numbers differ from run to run (they are timings).


rule table_time:
    message:
        "table_time from the job benchmark files"
    input:
        code=PIPE.steps["table_time"].code,
        clouds=TEST_CLOUDS,
        timed=[path for key in PIPE.keys("test") for path in (PIPE.normals_path("mfps", key),
                                                               layout.FEATURES.format(variant=FULL, cloud=key),
                                                               PIPE.normals_path(REFINENET, key))],
    output:
        **layout.TIME_FILES,
    params:
        tracked=tracked("table_time"),
    log:
        "logs/time/table_time.log",
    benchmark:
        "logs/time/table_time.benchmark.tsv"
    conda:
        "../envs/refinenet.yaml"
    shell:
        "python -m stages.time 2>&1 | tee {log}"
