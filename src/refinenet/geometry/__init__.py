"""Floor 2, local geometry shared by every stage: exact k-nearest neighbours (k-d tree and uniform grid),
covariances, and the per-point normal-tensor frames (docs/algorithm.md §4)."""
