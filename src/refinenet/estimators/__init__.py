"""Floor 3, normal estimators that need no training: the PCA and Jet baselines and MFPS, Refine-Net's initial
normals (docs/algorithm.md §2)."""
