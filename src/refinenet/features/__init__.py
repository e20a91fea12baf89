"""Floor 4, the network's inputs (docs/algorithm.md §3, §4, §6, §7): multi-scale bilateral filtering, height maps,
point patches, and the per-cloud feature cache."""
