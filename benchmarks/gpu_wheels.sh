#!/usr/bin/env bash
# Fill .whl/ (ignored by git) with what benchmarks/gpu_check.sh installs on a lent GPU machine,
# which reaches no package registry: pyopencl and the dependencies its image lacks, PyWavelets
# (the wavelet tests), setuptools and wheel (to build rsocl from the tree there), all for CPython
# 3.12 on x86-64 Linux, and rsocl's own wheel as a fallback. Run here, from any folder:
#
#     bash benchmarks/gpu_wheels.sh            # then carry ".whl" with the run (benchmarks/README.md)
#
# The image already holds NumPy, SciPy, scikit-image, h5py, imageio, matplotlib, tqdm, pytest,
# pytest-xdist, pytest-timeout, typing-extensions and PyTorch with CUDA.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
DEST="$ROOT/.whl"
PYTHON=${PYTHON:-python3}
# one version of each (two of one name stop the install there); pyopencl's is this project's tested one
PACKAGES=(pyopencl==2026.1.4 pytools==2026.1.1 platformdirs==4.14.8 siphash24==1.9 PyWavelets==1.9.0
          setuptools==84.2.1 wheel==0.48.0)

rm -rf "$DEST"
mkdir -p "$DEST"
platforms=()
for p in manylinux_2_28_x86_64 manylinux_2_27_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64 manylinux1_x86_64; do
    platforms+=(--platform "$p")
done
"$PYTHON" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    "${platforms[@]}" -d "$DEST" "${PACKAGES[@]}"
"$PYTHON" -m pip wheel -q --no-deps -w "$DEST" "$ROOT"
git -C "$ROOT" rev-parse --short HEAD > "$DEST/COMMIT"
ls -l "$DEST"
du -sh "$DEST"
