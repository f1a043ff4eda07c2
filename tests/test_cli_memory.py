"""pipeline.cli.keep_freed_memory: a one-shot command reuses its freed arrays' memory. The
independent truth is the kernel's count of the process's page faults (``ru_minflt``), in a
fresh interpreter (the setting stays with the process that takes it)."""

import platform
import subprocess
import sys

import pytest

#: Allocate, touch and free a 64 MB array 20 times; print the minor page faults it took.
SCRIPT = """
import resource, sys
import numpy as np
if sys.argv[1] == "keep":
    from pipeline.cli import keep_freed_memory
    assert keep_freed_memory()
np.ones(8 * 2 ** 20)  # the first array's pages: taken either way
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    np.ones(8 * 2 ** 20)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_freed_arrays_are_reused_not_faulted_in_again():
    """By default glibc serves each 64 MB array by its own mmap and returns it: each of the 20
    faults its pages in afresh (16,384 of 4 KB, fewer where the kernel gives huge pages: the
    count depends on the machine, so the two modes are compared); kept, the second to the
    twenty-first reuse the first's pages: under a tenth of the default's faults."""
    faults = {}
    for mode in ("default", "keep"):
        out = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, check=True)
        faults[mode] = int(out.stdout.split()[-1])
    assert faults["default"] >= 20, faults  # at least one fault an array: the default faults them in
    assert 10 * faults["keep"] < faults["default"], faults
