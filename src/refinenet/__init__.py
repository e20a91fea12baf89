"""Refine-Net: normal refinement for noisy point clouds (Zhou et al., TPAMI 2022), as a reproducible pipeline."""

__version__ = "0.5.0"
