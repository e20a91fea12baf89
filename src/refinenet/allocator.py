"""glibc's malloc thresholds for the pipeline's stages. By default glibc hands freed memory back to the kernel
early: a freed block above an adaptive threshold is unmapped, and free memory at the top of the heap is trimmed
above twice that threshold. A training step frees its batch's tensors and allocates them again the next step, so
the kernel unmaps, zeroes and faults in the same pages thousands of times: a training job spent a quarter of its
CPU time in the kernel. Fixed thresholds keep that memory for reuse (studies/results/allocator.md: the training
stage's CPU time 0.76x, its peak memory within 2%)."""

import ctypes
import sys

M_TRIM_THRESHOLD = -1  # mallopt parameters, from glibc's malloc.h
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 64 << 20  # above a CPU convolution's 50 MB buffer (batch 64); whole clouds' arrays are unmapped
TRIM_THRESHOLD = 256 << 20  # free memory kept at the top of the heap


def keep_freed_memory() -> bool:
    """Have glibc's malloc keep freed memory for reuse in this process; False where the C library is not glibc
    (macOS, musl), whose allocators are left as they are."""
    if not sys.platform.startswith("linux"):
        return False
    mallopt = getattr(ctypes.CDLL(None), "mallopt", None)
    if mallopt is None:
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
