# Initial normals by multi-scale fitting patch selection (MFPS, docs/algorithm.md §2) and its simple-MFPS
# ablation: one step each, as each feeds different consumers (MFPS: the features of every cloud). The shell
# command is formatted when a job runs, after the loop has ended, so the loop variable reaches it as a param.

for method in ("mfps", "simple_mfps"):

    rule:
        name:
            method
        message:
            f"{method} normals of {{wildcards.cloud}}"
        input:
            code=PIPE.steps[method].code,
            cloud=wf.CLOUD,
        output:
            PIPE.normals_path(method, "{cloud}"),
        params:
            tracked=tracked(method),
            method=method,
        log:
            wf.fill(wf.JOB_LOG, step=method),
        benchmark:
            wf.fill(wf.JOB_BENCHMARK, step=method),
        threads: 1
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.mfps --method {params.method} --cloud {input.cloud} --out {output}"
            " --threads {threads} 2>&1 | tee {log}"
