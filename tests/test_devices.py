"""Device choice and free-memory readings."""

from pathlib import Path

import pytest
import torch

from napari_lfdeblur._memory import host_available_memory
from napari_lfdeblur.devices import free_memory, select_device


def test_select_device():
    assert select_device("cpu") == torch.device("cpu")
    assert select_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(ValueError, match="unknown device"):
        select_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="no CUDA"):
            select_device("cuda")


@pytest.mark.skipif(not Path("/proc/meminfo").exists(), reason="needs /proc/meminfo")
def test_host_memory_matches_proc_meminfo():
    with open("/proc/meminfo") as fh:
        kib = next(int(line.split()[1]) for line in fh if line.startswith("MemAvailable:"))
    got = host_available_memory()
    assert got == pytest.approx(kib * 1024, rel=0.1)
    assert free_memory("cpu") == pytest.approx(got, rel=0.1)
