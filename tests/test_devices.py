"""Device choice and free-memory readings."""

from pathlib import Path

import pytest
import torch

from napari_lfdeblur import _memory
from napari_lfdeblur._memory import host_available_memory, release_host_memory
from napari_lfdeblur.devices import empty_cache, free_memory, select_device


def test_select_device():
    assert select_device("cpu") == torch.device("cpu")
    assert select_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    assert select_device(None) == select_device("auto")  # docstring: "'auto' (or None)"
    with pytest.raises(ValueError, match="unknown device"):
        select_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="no CUDA"):
            select_device("cuda")
    # a torch.device is checked like its name (not left to fail later inside torch)
    for kind in ("meta", "mps"):
        with pytest.raises(ValueError, match="unknown device"):
            select_device(torch.device(kind))
    assert select_device(torch.device("cpu")) == torch.device("cpu")
    with pytest.raises(ValueError, match="the CPU is 'cpu'"):  # torch has no second CPU device
        select_device("cpu:1")


def test_cuda_index_must_be_a_gpu_present(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    assert select_device("cuda:1") == torch.device("cuda:1")
    assert select_device("cuda") == torch.device("cuda")
    with pytest.raises(ValueError, match="'cuda:2' was asked for, but torch sees 2 CUDA GPU"):
        select_device("cuda:2")


def test_empty_cache_takes_a_device_name():
    empty_cache("cpu")  # a no-op; it needed a torch.device
    empty_cache(torch.device("cpu"))


def test_blur_operator_refuses_other_dtypes_and_devices():
    from napari_lfdeblur.blur import BlurOperator

    cp = [[-1.5, 0.0, 0.0], [1.5, 0.0, 0.0]]
    with pytest.raises(TypeError, match="floating-point torch dtype"):  # an integer dtype would round the path to views
        BlurOperator((3, 3, 8, 8), cp, n_times=4, dtype=torch.int32)
    with pytest.raises(TypeError, match="floating-point torch dtype"):
        BlurOperator((3, 3, 8, 8), cp, n_times=4, dtype="float32")
    op = BlurOperator((3, 3, 8, 8), cp, n_times=4, device="cpu")
    x = torch.rand(3, 3, 8, 8, 1)
    with pytest.raises(TypeError, match="dtype torch.float32"):  # not blurred in integers
        op.forward((100 * x).to(torch.int32))
    with pytest.raises(TypeError, match="dtype torch.float32"):
        op.adjoint(x.double())
    with pytest.raises(ValueError, match="the tensor is on meta, the operator on cpu"):
        op.forward(x.to("meta"))
    assert op.forward(x).dtype == torch.float32


@pytest.mark.skipif(not Path("/proc/meminfo").exists(), reason="needs /proc/meminfo")
def test_host_memory_matches_proc_meminfo():
    with open("/proc/meminfo") as fh:
        kib = next(int(line.split()[1]) for line in fh if line.startswith("MemAvailable:"))
    got = host_available_memory()
    assert got == pytest.approx(kib * 1024, rel=0.1)
    assert free_memory("cpu") == pytest.approx(got, rel=0.1)


@pytest.mark.skipif(not Path("/proc/meminfo").exists(), reason="needs /proc/meminfo")
def test_host_memory_without_psutil_reads_proc_meminfo_in_bytes(monkeypatch):
    import io
    import sys

    psutil = pytest.importorskip("psutil")
    want = psutil.virtual_memory().available
    monkeypatch.setitem(sys.modules, "psutil", None)  # as where psutil is not installed: its import fails
    assert host_available_memory() == pytest.approx(want, rel=0.1)
    # /proc/meminfo states kB meaning KiB (proc(5)): 1000 kB are 1024000 bytes, exactly
    meminfo = "MemTotal:        8000 kB\nMemFree:          500 kB\nMemAvailable:    1000 kB\n"
    real_open = open

    def fake_open(path, *args, **kwargs):
        return io.StringIO(meminfo) if path == "/proc/meminfo" else real_open(path, *args, **kwargs)

    monkeypatch.setattr(_memory, "open", fake_open, raising=False)  # found before the builtin by the module
    assert host_available_memory() == 1024000


def test_cpu_fallback_passes_a_cpu_run_through_and_reraises_cpu_errors():
    from napari_lfdeblur.devices import run_with_cpu_fallback
    from napari_lfdeblur.progress import run_to_completion

    seen = []

    def run(dev):
        seen.append(dev.type)
        yield 1
        return "ok"

    assert run_to_completion(run_with_cpu_fallback(run, torch.device("cpu"))) == "ok"
    assert seen == ["cpu"]

    def failing(dev):
        yield 1
        raise torch.cuda.OutOfMemoryError("out of memory")

    with pytest.raises(torch.cuda.OutOfMemoryError):  # no fall-back from the CPU itself
        run_to_completion(run_with_cpu_fallback(failing, torch.device("cpu")))


def test_release_host_memory_trims_glibc_heaps_on_linux_only(monkeypatch):
    calls = []

    class Libc:
        def malloc_trim(self, pad):
            calls.append(pad)
            return 1

    monkeypatch.setattr(_memory.ctypes, "CDLL", lambda name: Libc())
    monkeypatch.setattr(_memory.sys, "platform", "linux")
    release_host_memory()
    assert calls == [0]  # trim everything above the heap's top, keep no padding
    monkeypatch.setattr(_memory.sys, "platform", "darwin")
    release_host_memory()
    assert calls == [0]  # not called elsewhere

    class NoTrim:  # a C library without malloc_trim (musl)
        pass

    monkeypatch.setattr(_memory.sys, "platform", "linux")
    monkeypatch.setattr(_memory.ctypes, "CDLL", lambda name: NoTrim())
    release_host_memory()  # no error

