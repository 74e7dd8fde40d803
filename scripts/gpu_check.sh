#!/usr/bin/env bash
# The GPU check of issue 48 (experiments/gpu_check.rs), for a GPU machine with no Rust toolchain
# and no registry (../shared/notes/gpu.md).
#
#   scripts/gpu_check.sh pack          # here, on a CPU machine with Rust: ~25 min clean, ~3 min after
#                                      # (honours CARGO_TARGET_DIR)
#   scripts/gpu_check.sh run [ARGS]    # there, from the repository root, target/gpu_check carried
#
# `pack` builds the one binary with --features wgpu, strips and compresses it (~20 MB with xz),
# downloads Debian's Vulkan loader (the GPU machines had none) and copies PyTorch's two
# reference scripts, all into target/gpu_check/ (git-ignored: carry it). `run` unpacks the
# loader, points it at the NVIDIA driver's Vulkan ICD and runs the check in at most 8 minutes,
# writing to $OUT/gpu/<GPU name>/ (or reports/gpu/<GPU name>/ without $OUT); ARGS go to the
# binary (e.g. --parts decoders,neurokin).
set -euo pipefail
cd "$(dirname "$0")/.."
PACK=target/gpu_check

case "${1:-}" in
pack)
  cargo build --release --features wgpu --bin gpu_check
  rm -rf "$PACK" && mkdir -p "$PACK/debs" "$PACK/bench"
  strip -o "$PACK/gpu_check" "${CARGO_TARGET_DIR:-target}/release/gpu_check"
  xz -6 -T2 "$PACK/gpu_check"
  (cd "$PACK/debs" && apt-get download libvulkan1 >/dev/null)
  cp ../shared/bench/torch_reference.py ../shared/bench/torch_gpu_reference.py "$PACK/bench/"
  du -sh "$PACK"
  ;;
run)
  shift
  for deb in "$PACK"/debs/*.deb; do dpkg -x "$deb" /; done
  ldconfig 2>/dev/null || true
  for icd in /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json /usr/share/vulkan/icd.d/nvidia_icd.json; do
    if [ -f "$icd" ]; then export VK_DRIVER_FILES="$icd"; break; fi
  done
  xz -dkf "$PACK/gpu_check.xz" && chmod +x "$PACK/gpu_check"
  name=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 | tr -c 'A-Za-z0-9\n' '_' || true)
  name=${name:-unknown_gpu}
  out="${OUT:-reports}/gpu/$name"
  mkdir -p "$out"
  nvidia-smi > "$out/nvidia-smi.txt" 2>&1 || true
  timeout 480 "$PACK/gpu_check" --torch python3 --bench-dir "$PACK/bench" --out "$out" "$@"
  ;;
*)
  echo "usage: scripts/gpu_check.sh pack | run [gpu_check arguments]" >&2
  exit 2
  ;;
esac
