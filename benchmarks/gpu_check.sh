#!/usr/bin/env bash
# drpt on Dr.Jit's CUDA backend, on a machine with an NVIDIA GPU (at most 7 minutes:
# each step has its own time limit):
#
#   1. the render tests below with DRPT_BACKEND=cuda (drpt's kernels and the
#      Mitsuba references they compare with, cuda_ad_rgb);
#   2. one Mitsuba comparison on the GPU: python -m drpt compare ... --backend cuda;
#   3. the Cornell box's render samples/s on both backends (drpt bench, best of 3
#      after a warm-up render that compiles).
#
# Usage, from anywhere:  benchmarks/gpu_check.sh [OUTDIR]   (default: a temporary folder)
# PYTHON picks the interpreter (default .venv/bin/python, else python3).
# Without a usable GPU it prints one line and exits with status 2; a failed step
# exits with that step's status after saying which one.
set -uo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-.venv/bin/python}"
[ -x "$PY" ] || PY=python3
OUT="${1:-$(mktemp -d -t drpt_gpu_check.XXXXXX)}"
mkdir -p "$OUT"
CORNELL=scenes/cornellbox/cornellbox.txt

if ! "$PY" -c 'import sys, drjit as dr; sys.exit(0 if dr.has_backend(dr.JitBackend.CUDA) else 1)' \
        >/dev/null 2>&1; then
    echo "gpu_check: Dr.Jit finds no CUDA device or driver on this machine; nothing checked" >&2
    exit 2
fi

step() {  # step NAME SECONDS COMMAND...: run COMMAND with a time limit, stop on failure
    local name=$1 limit=$2
    shift 2
    echo "== $name"
    local t0=$SECONDS
    timeout "$limit" "$@"
    local rc=$?
    if [ $rc -ne 0 ]; then
        [ $rc -eq 124 ] && echo "gpu_check: $name: over ${limit} s" >&2
        echo "gpu_check: $name failed (status $rc)" >&2
        exit $rc
    fi
    echo "   ($((SECONDS - t0)) s)"
}

step "render tests, DRPT_BACKEND=cuda" 240 \
    env DRPT_BACKEND=cuda "$PY" -m pytest -q -x -p no:cacheprovider \
        tests/test_path_integrator.py tests/test_render_properties.py tests/test_whitted.py \
        tests/test_bundled_references.py

step "drpt vs Mitsuba (cuda_ad_rgb) on the Cornell box" 60 \
    "$PY" -m drpt compare "$CORNELL" --backend cuda --size 64 64 --spp 64 --ref-spp 1024 \
        --no-cache --out "$OUT/compare" --quiet

for backend in cuda llvm; do
    step "Cornell box samples/s, $backend" 60 \
        "$PY" -m drpt bench "$CORNELL" --backend "$backend" --accel auto --no-mitsuba \
            --size 256 256 --spp 64 --rays 262144 --repeat 3 --out "$OUT/bench_$backend"
done

"$PY" - "$OUT" <<'EOF'
import csv, sys
from pathlib import Path

rates = {}
for backend in ("cuda", "llvm"):
    with open(Path(sys.argv[1]) / f"bench_{backend}" / "bench.csv", newline="") as f:
        rates[backend] = float(next(csv.DictReader(f))["msamples_s"])
print(f"Cornell box 256x256, 64 spp: cuda {rates['cuda']:.2f} Msamples/s, "
      f"llvm {rates['llvm']:.2f} Msamples/s ({rates['cuda'] / rates['llvm']:.1f}x)")
EOF
echo "gpu_check: all passed; outputs in $OUT"
