# Normal-based clustering (docs/algorithm.md §5), fitted on the training clouds only; one step per variant whose
# overrides change it (e.g. the Kc sweep), full's serving the others.

for step in PIPE.family("clustering"):

    rule:
        name:
            step.name
        message:
            f"cluster model of {step.variant} (Kc = {PIPE.params[step.variant].clustering.n_clusters})"
        input:
            code=step.code,
            features=[files(step.variant, "features", layout.FEATURES, cloud=key) for key in TRAIN_KEYS],
        output:
            layout.CLUSTER_MODEL.format(variant=step.variant),
        params:
            tracked=tracked(step.name),
            variant=step.variant,
        log:
            f"logs/clustering/{step.variant}.log",
        benchmark:
            f"logs/clustering/{step.variant}.benchmark.tsv"
        priority: split_priority("train")  # on the way to training: before the test clouds' jobs
        conda:
            "../envs/refinenet.yaml"
        shell:
            "python -m stages.clustering --variant {params.variant} --features {input.features} --out {output}"
            " 2>&1 | tee {log}"
