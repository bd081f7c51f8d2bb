#!/usr/bin/env bash
# The GPU checks, in one run on a machine with a CUDA GPU: the CUDA tests, then the GPU benchmarks.
#
#   bash benchmarks/gpu_check.sh OUT_DIR [PYTHON]
#
# PYTHON (default python3) must have torch with CUDA, numpy, scipy, scikit-image, imageio, tifffile,
# h5py, matplotlib, tqdm and pytest; the package runs from this checkout (PYTHONPATH=src), not
# installed. bench_fullres.py reads the real captures from the folder LFDEBLUR_DATA names (see
# benchmarks/eval_set.py); without them its Illum cases are skipped. Into OUT_DIR go device.txt
# (torch, CUDA and the GPU), tests.log, and the tables bench_infinity_disparity.md (forward + adjoint
# against the memory-traffic floor), bench_rotation.md and bench_fullres.md. The exit status is 1
# when a test or a benchmark failed. Takes about 5-10 minutes on an H100/H200-class GPU (estimate:
# not yet run on one); the benchmarks come first in order of cost, so a run cut short keeps the
# cheap tables.
set -u -o pipefail
out=${1:?usage: gpu_check.sh OUT_DIR [PYTHON]}
py=${2:-python3}
mkdir -p "$out"
out=$(cd "$out" && pwd)
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1

"$py" -c "
import torch
assert torch.cuda.is_available(), 'torch sees no CUDA GPU'
print('torch', torch.__version__, 'CUDA', torch.version.cuda, torch.cuda.get_device_name(0))
" | tee "$out/device.txt" || exit 1

status=0
"$py" -m pytest -q -p no:cacheprovider tests/test_cuda.py tests/test_blur.py tests/test_rotation.py \
    tests/test_deconvolution.py tests/test_devices.py 2>&1 | tee "$out/tests.log" || status=1
"$py" benchmarks/bench_infinity_disparity.py --device cuda --n-times 32 --infinity-disparity 0 1 2 \
    --repeats 5 --out "$out/bench_infinity_disparity.md" || status=1
"$py" benchmarks/bench_rotation.py --device cuda --n-times 32 --repeats 5 --out "$out/bench_rotation.md" || status=1
"$py" benchmarks/bench_fullres.py --device cuda --max-memory 4 --out "$out/bench_fullres.md" || status=1
exit $status
