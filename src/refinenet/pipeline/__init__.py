"""Floor 7, the reproducibility pipeline (docs/design.md): the typed params, the step declarations shared by
Snakemake and DVC, the bridge between the two tools, and what every stage script shares."""
