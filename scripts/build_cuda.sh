#!/usr/bin/env bash
# Build selfmodel with burn's CUDA backend (`--features cuda`) where cubecl-llvm's build script
# would download an LLVM bundle: the same LLVM comes from PyPI instead, and nothing else is
# downloaded but the registries (crates.io, PyPI).
#
#   scripts/build_cuda.sh                         # cargo build --release --features cuda
#   scripts/build_cuda.sh --bin gpu_check         # arguments go to cargo build
#   FEATURES=wgpu,cuda scripts/build_cuda.sh ...  # both GPU backends in one binary
#   CARGO_COMMAND=check scripts/build_cuda.sh     # cargo check instead
#
# Into target/cuda/ (CARGO_TARGET_DIR to change it; the LLVM in target/cuda-llvm/, ~0.4 GB).
# Steps (issue 71):
# 1. PyPI's `mlc-llvm-static[all]` is the LLVM 23 cubecl-llvm wants (`[all]` carries the NVPTX
#    target), installed in a virtual environment;
# 2. its prefix is linked where tracel-llvm-bundler looks for its bundle,
#    `$XDG_DATA_HOME/tracel/tracel-llvm-<version in Cargo.lock>`, marked installed;
# 3. cargo builds with that XDG_DATA_HOME and the environment's python3 (>= 3.10) first on PATH:
#    the package's `llvm-config` is a Python script.
# At run time cudarc loads the driver's libcuda; nothing of CUDA is needed to build.
# Not part of CI: a second burn build would double CI's time.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD/target/cuda-llvm
venv=$root/venv
LLVM_PACKAGE='mlc-llvm-static[all]==23.1.1.post0'

python=""
for p in python3.13 python3.12 python3.11 python3.10 python3; do
  if command -v "$p" >/dev/null && "$p" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null; then
    python=$p
    break
  fi
done
if [ -z "$python" ]; then
  echo "error: build_cuda.sh needs a python3 >= 3.10 with venv (the LLVM's llvm-config is a Python script)" >&2
  exit 1
fi
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c 'import mlc_llvm_static' 2>/dev/null; then
  echo "== the LLVM from PyPI ($LLVM_PACKAGE) into $venv"
  rm -rf "$venv"
  "$python" -m venv "$venv"
  "$venv/bin/pip" install -q --upgrade pip
  "$venv/bin/pip" install -q "$LLVM_PACKAGE"
fi
prefix=$("$venv/bin/python" -m mlc_llvm_static.config --prefix)
version=$(awk '/^name = "tracel-llvm-bundler"/ { getline; gsub(/[^0-9.-]/, ""); print; exit }' Cargo.lock)
if [ -z "$version" ]; then
  echo "error: no tracel-llvm-bundler in Cargo.lock: is the cuda feature's dependency tree there?" >&2
  exit 1
fi
mkdir -p "$root/data/tracel"
ln -sfn "$prefix" "$root/data/tracel/tracel-llvm-$version"
touch "$prefix/.tracel-llvm-installed"
echo "== LLVM $version: $prefix"

export XDG_DATA_HOME=$root/data
export PATH=$venv/bin:$PATH
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$PWD/target/cuda}
exec cargo "${CARGO_COMMAND:-build}" --release --features "${FEATURES:-cuda}" "$@"
