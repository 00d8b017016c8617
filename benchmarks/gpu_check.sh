#!/usr/bin/env bash
# One prepared check on a lent NVIDIA GPU machine (H100 or H200, no network, PyTorch with CUDA
# preinstalled as python3), in one command of at most the sum of the caps (620 s) and the install:
#   1. install pyopencl and the rest from the carried wheels (.whl/, made by benchmarks/gpu_wheels.sh)
#      and rsocl from this tree into /tmp/site; point pyopencl's ICD loader at NVIDIA's OpenCL;
#   2. the test suite on NVIDIA's OpenCL (RSOCL_DEVICE=nvidia), pytest-xdist, capped, with rsocl's own settings;
#      any of its processes still running after it (an xdist worker past the cap) is killed;
#   3. benchmarks/lanes_choice.py (the projection's 1, 2, 4 and 8 lanes at 50×50, one set and batches as the
#      search's, and at 128 and 256 pixels; no case starts after 3/5 of the cap), capped; its choice is exported
#      as RSOCL_BENCH_PROJECT_LANES, which every later benchmark applies and names in its page's header
#      (benchmarks/provenance.py);
#   4. benchmarks/blocks.py (the operator kernels' block layout, GPU_BLOCK), capped: only where STEPS names it;
#   5. benchmarks/peer.py (rsocl against PyTorch eager, CUDA graph and torch.compile; in four cases also one lane
#      beside the chosen count, or 4 and 8 lanes where one was chosen), capped;
#   6. benchmarks/launches.py where the tree has it (the device's path, the plain TV in two launches per
#      iteration and in one per two iterations, the fused TV: what GPU_ONE_LAUNCH and GPU_FUSED rest on), then
#      benchmarks/launch_cost.py (a launch's host time by arguments and grid) and benchmarks/kernel_times.py (an
#      iteration's device time kernel by kernel, busy against span; then at 50×50 on the search's batches of 4, 5
#      and 9 sets), all into check.log, capped;
#   7. benchmarks/call_cost.py where the tree has it (a small call with device buffers pooled or made each call), capped;
#   8. benchmarks/search_launches.py (the self-tuned default against a fixed run, two scenes, 50 to 256 pixels), then
#      benchmarks/tuned_phases.py (where the self-tuned call's time goes, phase by phase), capped;
#   9. one set of the paper configuration: call and loop times at 1 and 200 iterations, and its host work under
#      cProfile; then a self-tuned call's host work at 50×50 under cProfile.
# Eight files go to $OUT (the device tool's folder that comes back, at most 8 files; ./out/gpu elsewhere): check.log
# (every step but the tests, the lanes page included), tests.log, peer.md, launches.md, call_cost.md,
# search_launches.md, tuned_phases.md, profile.txt (blocks.md too where STEPS names blocks: then name at most seven
# of the others' steps).
# Run from the device tool (benchmarks/README.md), with the commit named, e.g.:
#     RSOCL_GIT_COMMIT=abc1234 bash benchmarks/gpu_check.sh          # carry: [".whl"]
# Knobs: STEPS (tests lanes peer launches call search phases profile; blocks may be added) the steps run after the
# install; TEST_ARGS (none: the whole suite) pytest's arguments; TEST_WORKERS (12), TEST_CAP (120), LANES_CAP (50),
# PEER_CAP (180), LAUNCH_CAP (40), CALL_CAP (30), SEARCH_CAP (70), PHASES_CAP (40), PROFILE_CAP (30), BLOCKS_CAP (80),
# COST_CAP (20), KTIME_CAP (20) in seconds; PEER_ARGS and BLOCKS_ARGS replace those scripts' arguments;
# RSOCL_BENCH_PROJECT_LANES, set before the run, stands for the lanes step's choice;
# DEVICE (nvidia): rsocl's device spec (another spec skips the NVIDIA ICD step: a dry run on a CPU).
set -uo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
OUT=${OUT:-$ROOT/out/gpu}
mkdir -p "$OUT"
PYTHON=${PYTHON:-python3}
SITE=${SITE:-/tmp/site} BUILD=${BUILD:-/tmp/build-tools}
DEVICE=${DEVICE:-nvidia}
TEST_CAP=${TEST_CAP:-120} PEER_CAP=${PEER_CAP:-180} LAUNCH_CAP=${LAUNCH_CAP:-40} CALL_CAP=${CALL_CAP:-30}
SEARCH_CAP=${SEARCH_CAP:-70} PROFILE_CAP=${PROFILE_CAP:-30} BLOCKS_CAP=${BLOCKS_CAP:-80} COST_CAP=${COST_CAP:-20}
KTIME_CAP=${KTIME_CAP:-20} PHASES_CAP=${PHASES_CAP:-40} LANES_CAP=${LANES_CAP:-50}
STEPS=" ${STEPS:-tests lanes peer launches call search phases profile} "
want() { [[ "$STEPS" == *" $1 "* ]]; }
BLOCKS_ARGS=${BLOCKS_ARGS:---rounds 3 --cases paper batch64 size128 size256 size512}
export PYTHONUNBUFFERED=1 POCL_CACHE_DIR=/tmp/pocl-cache
T0=$(date +%s)
stamp() { echo "=== [$(( $(date +%s) - T0 )) s] $*"; }
if [ -z "${RSOCL_GIT_COMMIT:-}" ] && [ -f .whl/COMMIT ]; then
    export RSOCL_GIT_COMMIT="$(cat .whl/COMMIT) (from .whl/COMMIT: the wheels' commit, not necessarily this tree's)"
fi

# ---------------------------------------------------------------- 1. install, OpenCL platform
{
stamp "install"
ls .whl/pyopencl-*.whl >/dev/null 2>&1 || { echo "no .whl/pyopencl-*.whl: run benchmarks/gpu_wheels.sh here and carry .whl"; exit 2; }
"$PYTHON" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$BUILD" \
    .whl/setuptools-*.whl .whl/wheel-*.whl || exit 2
"$PYTHON" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" \
    $(ls .whl/*.whl | grep -v -e '/rsocl-' -e '/setuptools-' -e '/wheel-') || exit 2
if PYTHONPATH="$BUILD:$SITE" "$PYTHON" -m pip install -q --no-index --no-deps --no-build-isolation --no-compile \
        --no-cache-dir --upgrade --target "$SITE" . ; then
    echo "rsocl installed from this tree"
else
    echo "WARNING: building rsocl from this tree failed; installing the carried .whl/rsocl-*.whl (commit $(cat .whl/COMMIT 2>/dev/null))"
    "$PYTHON" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" .whl/rsocl-*.whl || exit 2
fi
# pyopencl's wheel brings an ICD loader; where the driver ships no vendors file, name NVIDIA's library
if [ "$DEVICE" = nvidia ] && [ ! -e /etc/OpenCL/vendors/nvidia.icd ]; then
    lib=$(ldconfig -p 2>/dev/null | awk '/libnvidia-opencl\.so\.1/ {print $NF; exit}')
    [ -n "$lib" ] || lib=$(ls /usr/local/nvidia/lib64/libnvidia-opencl.so.1 /usr/lib/x86_64-linux-gnu/libnvidia-opencl.so.1 2>/dev/null | head -1)
    [ -n "$lib" ] || { echo "libnvidia-opencl.so.1 not found: no NVIDIA OpenCL here"; exit 3; }
    rm -rf /tmp/icd && mkdir -p /tmp/icd && echo "$lib" > /tmp/icd/nvidia.icd
    export OCL_ICD_VENDORS=/tmp/icd
    echo "OCL_ICD_VENDORS=/tmp/icd -> $lib"
fi
} 2>&1 | tee "$OUT/check.log"
[ "${PIPESTATUS[0]}" = 0 ] || exit 1
[ -e /tmp/icd/nvidia.icd ] && export OCL_ICD_VENDORS=/tmp/icd
# PYTHONSAFEPATH (-P for every process, the tests' subprocesses too): the installed rsocl, never the
# source folder rsocl/ of the working directory (which lacks rsocl.kernels)
export PYTHONPATH="$SITE" RSOCL_DEVICE="$DEVICE" PYTHONSAFEPATH=1
"$PYTHON" -P -c "import rsocl; print('rsocl', rsocl.__file__); import torch; print('torch', torch.__version__, 'CUDA', torch.cuda.is_available())" 2>&1 | tee -a "$OUT/check.log"
"$PYTHON" -P -m rsocl.cli devices 2>&1 | tee -a "$OUT/check.log"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>&1 | tee -a "$OUT/check.log"

# ---------------------------------------------------------------- 2. the test suite on the GPU
if want tests; then
stamp "tests (cap ${TEST_CAP} s)" | tee "$OUT/tests.log"
flags=()
"$PYTHON" -c "import xdist" 2>/dev/null && flags+=(-n "${TEST_WORKERS:-12}")              # pytest-xdist and pytest-timeout: in the image
"$PYTHON" -c "import pytest_timeout" 2>/dev/null && flags+=(--timeout 120)
# the tests' processes carry a mark in their environment: any left running past the cap (an xdist worker that
# did not stop) is killed, so that it takes no host or device time from the benchmarks after it
mark="RSOCL_GPU_CHECK_TESTS=$$"
# shellcheck disable=SC2086
timeout -k 10 "$TEST_CAP" env -u RSOCL_BENCH_PROJECT_LANES "$mark" "$PYTHON" -P -m pytest -q -p no:cacheprovider \
    "${flags[@]}" -rfEs ${TEST_ARGS:-} 2>&1 | tee -a "$OUT/tests.log" | tail -n 60
echo "tests exit status ${PIPESTATUS[0]} (124: stopped at the cap)" | tee -a "$OUT/tests.log"
left=$(grep -lsxz -- "$mark" /proc/[0-9]*/environ | cut -d/ -f3 | tr '\n' ' ')
if [ -n "$left" ]; then
    # shellcheck disable=SC2086
    kill -KILL $left 2>/dev/null
    echo "killed the processes the tests left running: $left" | tee -a "$OUT/tests.log" "$OUT/check.log"
fi
fi

# ---------------------------------------------------------------- 3. the projection's lanes, chosen by their device time
if want lanes; then
    stamp "benchmarks/lanes_choice.py (cap ${LANES_CAP} s)" | tee -a "$OUT/check.log"
    rm -f /tmp/lanes_choice.txt
    # no case starts after three fifths of the cap: the last one has the rest to finish, and the choice is made
    timeout -k 5 "$LANES_CAP" "$PYTHON" -P benchmarks/lanes_choice.py --device "$DEVICE" --budget $((LANES_CAP * 3 / 5)) \
        --choice /tmp/lanes_choice.txt >> "$OUT/check.log" 2>&1
    echo "lanes_choice exit status $?" | tee -a "$OUT/check.log"
    if [ -s /tmp/lanes_choice.txt ]; then
        export RSOCL_BENCH_PROJECT_LANES=$(cat /tmp/lanes_choice.txt)
        echo "the benchmarks below run with RSOCL_BENCH_PROJECT_LANES=$RSOCL_BENCH_PROJECT_LANES" | tee -a "$OUT/check.log"
    fi
fi
# the peer's lanes variants: 4 and 8 beside one lane, or one lane beside the chosen count
others="4 8"
[ "${RSOCL_BENCH_PROJECT_LANES:-1}" = 1 ] || others=1
PEER_ARGS=${PEER_ARGS:---rounds 2 --cases paper batch64 size64 size128 size256 size512 batch256 --no-first-two --project-lanes $others --variant-cases paper batch64 size64 size128}

# ---------------------------------------------------------------- 4. the block layout of the operator kernels
if want blocks; then
    stamp "benchmarks/blocks.py (cap ${BLOCKS_CAP} s)" | tee -a "$OUT/check.log"
    # shellcheck disable=SC2086
    timeout -k 5 "$BLOCKS_CAP" "$PYTHON" -P benchmarks/blocks.py --device "$DEVICE" $BLOCKS_ARGS --out "$OUT/blocks.md" \
        >> "$OUT/check.log" 2>&1
    echo "blocks exit status $?" | tee -a "$OUT/check.log"
fi

# ---------------------------------------------------------------- 5. the PyTorch peer
if want peer; then
stamp "benchmarks/peer.py $PEER_ARGS (cap ${PEER_CAP} s)" | tee -a "$OUT/check.log"
# shellcheck disable=SC2086
timeout -k 10 "$PEER_CAP" "$PYTHON" -P benchmarks/peer.py --device "$DEVICE" --out "$OUT/peer.md" $PEER_ARGS 2>&1 \
    | tee -a "$OUT/check.log" | grep -v '^|' | tail -n 40
echo "peer exit status ${PIPESTATUS[0]} (124: stopped at the cap; the page holds the cases done)" | tee -a "$OUT/check.log"
fi

# ---------------------------------------------------------------- 6. launches per iteration
if want launches; then
    stamp "benchmarks/launches.py (cap ${LAUNCH_CAP} s)" | tee -a "$OUT/check.log"
    timeout -k 5 "$LAUNCH_CAP" "$PYTHON" -P benchmarks/launches.py --device "$DEVICE" --rounds 3 --paths device gpu-two gpu-pairs lean \
        --out "$OUT/launches.md" \
        >> "$OUT/check.log" 2>&1
    echo "launches exit status $?" | tee -a "$OUT/check.log"
    stamp "benchmarks/launch_cost.py (cap ${COST_CAP} s)" | tee -a "$OUT/check.log"
    timeout -k 5 "$COST_CAP" "$PYTHON" -P benchmarks/launch_cost.py --device "$DEVICE" --rounds 5 >> "$OUT/check.log" 2>&1
    echo "launch_cost exit status $?" | tee -a "$OUT/check.log"
    stamp "benchmarks/kernel_times.py (cap ${KTIME_CAP} s)" | tee -a "$OUT/check.log"
    timeout -k 5 "$KTIME_CAP" "$PYTHON" -P benchmarks/kernel_times.py --device "$DEVICE" --sizes 8 50 128 256 \
        --iterations 40 >> "$OUT/check.log" 2>&1
    echo "kernel_times exit status $?" | tee -a "$OUT/check.log"
    # the self-tuned search's batches at 50×50 (4 to 9 sets), kernel by kernel: where its device time goes
    stamp "benchmarks/kernel_times.py, batches (cap ${KTIME_CAP} s)" | tee -a "$OUT/check.log"
    timeout -k 5 "$KTIME_CAP" "$PYTHON" -P benchmarks/kernel_times.py --device "$DEVICE" --sizes 50 --sets 4 5 9 \
        --iterations 40 >> "$OUT/check.log" 2>&1
    echo "kernel_times (batches) exit status $?" | tee -a "$OUT/check.log"
fi

# ---------------------------------------------------------------- 7. a small call's cost: buffers pooled or made
if want call; then
    stamp "benchmarks/call_cost.py (cap ${CALL_CAP} s)" | tee -a "$OUT/check.log"
    timeout -k 5 "$CALL_CAP" "$PYTHON" -P benchmarks/call_cost.py --device "$DEVICE" --sizes 8 50 --rounds 3 --calls 5 \
        --out "$OUT/call_cost.md" >> "$OUT/check.log" 2>&1
    echo "call_cost exit status $?" | tee -a "$OUT/check.log"
fi

# ---------------------------------------------------------------- 8. the self-tuned default against a fixed run
if want search; then
    stamp "benchmarks/search_launches.py (cap ${SEARCH_CAP} s)" | tee -a "$OUT/check.log"
    timeout -k 5 "$SEARCH_CAP" "$PYTHON" -P benchmarks/search_launches.py --device "$DEVICE" --sizes 50 128 256 \
        --out "$OUT/search_launches.md" >> "$OUT/check.log" 2>&1
    echo "search_launches exit status $?" | tee -a "$OUT/check.log"
fi
if want phases; then
    stamp "benchmarks/tuned_phases.py (cap ${PHASES_CAP} s)" | tee -a "$OUT/check.log"
    timeout -k 5 "$PHASES_CAP" "$PYTHON" -P benchmarks/tuned_phases.py --device "$DEVICE" --size 50 --rounds 5 \
        --out "$OUT/tuned_phases.md" >> "$OUT/check.log" 2>&1
    echo "tuned_phases exit status $?" | tee -a "$OUT/check.log"
fi

# ---------------------------------------------------------------- 9. one paper set's host work, profiled
if want profile; then
stamp "profile of one paper set (cap ${PROFILE_CAP} s)" | tee -a "$OUT/check.log"
timeout -k 5 "$PROFILE_CAP" "$PYTHON" -P - > "$OUT/profile.txt" 2>&1 <<'PY'
import cProfile, pstats, statistics, sys, time
sys.path.insert(0, "benchmarks")
import numpy as np, rsocl
from paper_config import paper_rig
from rsocl.model.scenes import builtin_scene
rig = paper_rig()
g = rsocl.RollingShutterOperator(rig).forward(builtin_scene(rig.shape, rig.T, seed=0))
opts = dict(lam=0.1, eta=0.2, tune=False)
for _ in range(3):
    rsocl.reconstruct(g, rig, iterations=200, **opts)
for it in (1, 200):
    walls, loops = [], []
    for _ in range(10):
        t0 = time.perf_counter(); res = rsocl.reconstruct(g, rig, iterations=it, **opts)
        walls.append(time.perf_counter() - t0); loops.append(float(res.history["time"][-1]))
    print(f"{it} iterations: call {statistics.median(walls) * 1e3:.2f} ms, loop {statistics.median(loops) * 1e3:.2f} ms (medians of 10)")
prof = cProfile.Profile(); prof.enable()
for _ in range(5):
    rsocl.reconstruct(g, rig, iterations=200, **opts)
prof.disable()
for key in ("tottime", "cumulative"):
    pstats.Stats(prof).sort_stats(key).print_stats(30)
print("=== 20 calls of 1 iteration (the fixed cost of a call)")
prof = cProfile.Profile(); prof.enable()
for _ in range(20):
    rsocl.reconstruct(g, rig, iterations=1, **opts)
prof.disable()
pstats.Stats(prof).sort_stats("cumulative").print_stats(45)
print("=== 5 self-tuned calls at 50×50 (the built-in scene, the default rung)")
from launches import case
rig, g = case(50)
for _ in range(2):
    rsocl.reconstruct(g, rig)
prof = cProfile.Profile(); prof.enable()
for _ in range(5):
    rsocl.reconstruct(g, rig)
prof.disable()
for key in ("tottime", "cumulative"):
    pstats.Stats(prof).sort_stats(key).print_stats(40)
PY
echo "profile exit status $?" | tee -a "$OUT/check.log"
head -n 2 "$OUT/profile.txt"
fi

stamp "done; the peer's page:"
if [ -f "$OUT/peer.md" ]; then sed -n '/^## Times/,$p' "$OUT/peer.md"; else echo "(no peer.md: the peer step did not run)"; fi
