"""The enhancer's frames reuse the pages of the frames before (fovexp.memory), measured in
page faults."""

import subprocess
import sys

import pytest

SCRIPT = r"""
import resource, sys
import numpy as np
if sys.argv[1] == "enhancer":  # as a user meets it: an Enhancer sets it up
    import fovexp.memory
    from fovexp import Enhancer, load_display
    Enhancer(load_display("lg-oled55cx"))
    if not fovexp.memory._done:  # -2: the Enhancer did not set it; -1: the C library refused
        print(-2 if fovexp.memory.retain_freed_memory() else -1)
        sys.exit()
faults = []
for _ in range(3):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.empty(200 << 20, np.uint8)
    a.fill(1)  # every page written
    del a
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(faults[-1])
"""


def _faults(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True,
                         check=True, env={"PATH": "/usr/bin:/bin"})
    return int(out.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt only")
def test_a_frame_sized_array_reuses_the_freed_pages():
    """A 200 MB array written, freed and written again: once an Enhancer has been made, the
    third costs (almost) no page faults; with glibc's defaults it faults again every time
    (4 KB or 2 MB pages: at least 100 faults)."""
    assert _faults("default") >= 100
    retained = _faults("enhancer")
    assert retained != -2, "an Enhancer did not call fovexp.memory.retain_freed_memory"
    if retained == -1:
        pytest.skip("this C library refused the setting (fovexp.memory)")
    assert retained < 50


def test_the_setting_is_left_alone_on_request(monkeypatch):
    import fovexp.memory as memory

    monkeypatch.setattr(memory, "_done", False)
    monkeypatch.setenv("FOVEXP_MALLOC_DEFAULTS", "1")
    assert memory.retain_freed_memory() is False
