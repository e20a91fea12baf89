# Feature cache per cloud: multi-scale filtered normals, per-point frames, height maps (docs/algorithm.md §3, §4, §7).
# One step per variant whose overrides change the features (full's serves the others). The shell command is
# formatted when a job runs, after the loop has ended, so the loop variable reaches it as a param.

for step in PIPE.family("features"):

    rule:
        name:
            step.name
        message:
            f"features ({step.variant}) of {{wildcards.cloud}}"
        input:
            code=step.code,
            cloud=layout.CLOUD,
            initial=PIPE.initial_path(step.variant, "{cloud}"),
        output:
            layout.fill(layout.FEATURES, variant=step.variant),
        params:
            tracked=tracked(step.name),
            variant=step.variant,
        log:
            layout.fill(layout.JOB_LOG, step=f"features/{step.variant}"),
        benchmark:
            layout.fill(layout.JOB_BENCHMARK, step=f"features/{step.variant}"),
        threads: 1
        priority: lambda wildcards: split_priority(wildcards.cloud.split("/")[0])
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.features --variant {params.variant} --cloud {input.cloud} --initial {input.initial}"
            " --out {output} --threads {threads} 2>&1 | tee {log}"
