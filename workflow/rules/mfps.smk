# Initial normals by multi-scale fitting patch selection (MFPS, docs/algorithm.md §2): on the test clouds together
# with its simple-MFPS ablation, which the same fitted patches give (one job for both), and on the training clouds
# (mfps_train) alone. Training clouds' jobs go first (`split_priority`). The shell command is formatted when a job
# runs, after the loop has ended, so what differs between the steps reaches it as a param.

for step in PIPE.family("mfps"):
    methods = [m for m in MFPS_METHODS if PIPE.normals_dir(m, step.split) in step.outs]
    simple_out = f"--simple-out {PIPE.normals_path('simple_mfps', '{cloud}')}" if "simple_mfps" in methods else ""

    rule:
        name:
            step.name
        message:
            f"{' and '.join(methods)} normals of {{wildcards.cloud}}"
        input:
            code=step.code,
            cloud=layout.CLOUD,
        output:
            **{m: PIPE.normals_path(m, "{cloud}") for m in methods},
        wildcard_constraints:
            cloud=rf"{step.split}/[^/]+/[^/]+",
        params:
            tracked=tracked(step.name),
            simple_out=simple_out,
        log:
            layout.fill(layout.JOB_LOG, step=step.name),
        benchmark:
            layout.fill(layout.JOB_BENCHMARK, step=step.name),
        threads: 1
        priority: split_priority(step.split)
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.mfps --cloud {input.cloud} --out {output.mfps} {params.simple_out} --threads {threads}"
            " 2>&1 | tee {log}"
