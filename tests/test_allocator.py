"""`refinenet.allocator`: with its thresholds, memory freed and allocated again is reused instead of being faulted
in anew, on the pattern a training step makes (several batch-sized blocks allocated, then all freed)."""

import subprocess
import sys

import pytest

PATTERN = """
import resource, sys
import numpy as np
from refinenet.allocator import keep_freed_memory
if sys.argv[1] == "kept":
    assert keep_freed_memory()
start = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(50):
    blocks = [np.ones(1 << 20) for _ in range(3)]  # 8 MB each: heap blocks once glibc's threshold has adapted
    del blocks
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - start)
"""


def minor_faults(setting: str) -> int:
    done = subprocess.run([sys.executable, "-c", PATTERN, setting], capture_output=True, text=True, check=True)
    return int(done.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the thresholds are glibc's")
def test_kept_memory_is_not_faulted_in_again():
    # 50 rounds of three 8 MB blocks: glibc's default trims the heap every round and faults ~4 MB in again
    # (measured 50,985 faults in all); kept, the first round's pages serve them all (measured 1,533)
    default, kept = minor_faults("default"), minor_faults("kept")
    assert default > 25_000
    assert kept < 5_000
