"""Refine-Net: normal refinement for noisy point clouds (Zhou et al., TPAMI 2022), as a reproducible pipeline."""

from pathlib import Path

__version__ = "0.5.0"
#: Where the package keeps its shipped release (a copy of one profile's `results/release`). Here, not in
#: `network.release`, so that a command checks its files against it before importing torch.
SHIPPED = Path(__file__).resolve().parent / "shipped"
