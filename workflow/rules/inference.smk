# Refine-Net normals of every test cloud, merged across clusters, in the PCPNet format (docs/algorithm.md §10);
# one step per variant.

for step in PIPE.family("inference"):

    rule:
        name:
            step.name
        message:
            f"Refine-Net ({step.variant}) normals of {{wildcards.cloud}}"
        input:
            code=step.code,
            cloud=layout.CLOUD,
            features=files(step.variant, "features", layout.FEATURES),
            clusters=files(step.variant, "clustering", layout.CLUSTER_MODEL),
            networks=networks(step.variant),
        output:
            layout.fill(layout.REFINED, variant=step.variant),
        params:
            tracked=tracked(step.name),
            variant=step.variant,
        log:
            layout.fill(layout.JOB_LOG, step=f"inference/{step.variant}"),
        benchmark:
            layout.fill(layout.JOB_BENCHMARK, step=f"inference/{step.variant}"),
        threads: 1
        resources:
            gpu=gpus(PIPE.params[step.variant].inference.device),
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.inference --variant {params.variant} --cloud {input.cloud} --features {input.features}"
            " --clusters {input.clusters} --networks {input.networks} --out {output} --threads {threads}"
            " 2>&1 | tee {log}"
