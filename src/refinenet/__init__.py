"""Refine-Net: normal refinement for noisy point clouds (Zhou et al., TPAMI 2022), as a reproducible pipeline."""

import os
from pathlib import Path

#: MKL's strict reproducible mode: torch's float32 GEMMs of large K (the output module's 2112 inputs) otherwise
#: split their sums by thread on AVX-512 CPUs, and a one-thread tile job disagreed with a two-thread process in
#: the last bit. With it results are bitwise equal at any thread count, at no measured cost. MKL reads it at its
#: first call, so it holds even where torch was imported first.
os.environ.setdefault("MKL_CBWR", "AUTO,STRICT")

__version__ = "0.5.0"
#: Where the package keeps its shipped release (the pipeline's `release` step writes it). Here, not in
#: `network.release`, so that a command checks its files against it before importing torch.
SHIPPED = Path(__file__).resolve().parent / "shipped"
