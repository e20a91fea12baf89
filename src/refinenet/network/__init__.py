"""Floor 6, Refine-Net itself (docs/algorithm.md §5, §8-§10): normal-based clustering, the network, its samples,
per-cluster training and whole-cloud inference."""
