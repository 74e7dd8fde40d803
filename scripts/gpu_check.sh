#!/usr/bin/env bash
# The GPU check of issue 48 (experiments/gpu_check.rs), for a GPU machine with no Rust toolchain
# and no registry (../shared/notes/gpu.md).
#
#   scripts/gpu_check.sh pack          # here, on a CPU machine with Rust: ~25 min clean per build,
#                                      # ~3 min after (honours CARGO_TARGET_DIR; the SPIR-V build
#                                      # in target/vulkan)
#   scripts/gpu_check.sh run [ARGS]    # there, from the repository root, target/gpu_check carried
#   GPU_CHECK_PACK=target/gpu_check_spirv scripts/gpu_check.sh run   # the same under SPIR-V
#
# `pack` builds the binary twice, once per shader compiler: --features wgpu (WGSL through naga)
# into target/gpu_check/ and --features vulkan (SPIR-V) into target/gpu_check_spirv/, each
# stripped and compressed (~20 MB with xz) with Debian's Vulkan loader and the GL dispatch
# libraries the NVIDIA driver's Vulkan library links (the GPU machines had neither) and
# PyTorch's two reference scripts (git-ignored: carry one folder a call, the tree is ~34 MB of
# the 64 MiB a call carries). `run` unpacks the loader, points it at the NVIDIA driver's Vulkan
# ICD and runs the check in at most 8 minutes, writing to $OUT/gpu/<GPU name>/ (or
# reports/gpu/<GPU name>/ without $OUT; .../spirv/ for the SPIR-V pack); ARGS go to the binary
# (e.g. --threads 2,16); GPU_CHECK_PARTS picks the parts (default: all, in the order below; the
# SPIR-V pack: decoders, neurokin, warm, equivalence and precision) and GPU_CHECK_SECONDS (default 480) bounds the run.
# `warm` runs the neurokin part again in a new process: cubecl keeps its autotune results (and,
# under SPIR-V, the compiled kernels) in target/environment/, which the first run of the
# session filled from empty (CUBECL_ENVIRONMENT names a fresh one), so the two give the
# first-run and second-run times.
set -euo pipefail
cd "$(dirname "$0")/.."
PACK=${GPU_CHECK_PACK:-target/gpu_check}

case "${1:-}" in
pack)
  for build in "wgpu target/gpu_check ${CARGO_TARGET_DIR:-target}" "vulkan target/gpu_check_spirv target/vulkan"; do
    set -- $build
    CARGO_TARGET_DIR=$3 cargo build --release --features "$1" --bin gpu_check
    rm -rf "$2" && mkdir -p "$2/debs" "$2/bench"
    strip -o "$2/gpu_check" "$3/release/gpu_check"
    xz -6 -T2 "$2/gpu_check"
    echo "$1" >"$2/feature"
    (cd "$2/debs" && apt-get download libvulkan1 libglvnd0 libegl1 libgl1 libglx0 libopengl0 libgles2 \
      libx11-6 libxcb1 libxau6 libxdmcp6 libbsd0 libmd0 libxext6 >/dev/null)
    cp ../shared/bench/torch_reference.py ../shared/bench/torch_gpu_reference.py \
      scripts/torch_step_kernels.py "$2/bench/"
    du -sh "$2"
  done
  ;;
run)
  shift
  for deb in "$PACK"/debs/*.deb; do dpkg -x "$deb" /; done
  ldconfig 2>/dev/null || true
  icd=$(ls /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd*.json /usr/share/vulkan/icd.d/nvidia_icd*.json \
    /etc/vulkan/icd.d/nvidia_icd*.json 2>/dev/null | head -1 || true)
  [ -n "$icd" ] || icd=$(find / -xdev -name 'nvidia_icd*.json' 2>/dev/null | head -1 || true)
  if [ -n "$icd" ]; then export VK_DRIVER_FILES="$icd"; fi
  echo "Vulkan ICD: ${icd:-none found}"
  xz -dkf "$PACK/gpu_check.xz" && chmod +x "$PACK/gpu_check"
  name=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 | tr -c 'A-Za-z0-9\n' '_' || true)
  name=${name:-unknown_gpu}
  out="${OUT:-reports}/gpu/$name"
  parts="decoders neurokin warm equivalence precision counts profile k3dgs fill cpu split"
  if [ "$(cat "$PACK/feature" 2>/dev/null)" = vulkan ]; then
    out="$out/spirv"
    parts="decoders neurokin warm equivalence precision"
  fi
  mkdir -p "$out"
  # A fresh cubecl environment: the first neurokin run tunes and compiles from nothing.
  export CUBECL_ENVIRONMENT="gpu_check_$(date +%s)"
  nvidia-smi > "$out/nvidia-smi.txt" 2>&1 || true
  # One process a part, each under its own limit (at most 240 s, and what is left of the run's),
  # so a part that hangs or aborts costs only itself; the console goes on across them.
  rm -f "$out/console.txt"
  deadline=$(( $(date +%s) + ${GPU_CHECK_SECONDS:-480} ))
  for part in ${GPU_CHECK_PARTS:-$parts}; do
    left=$(( deadline - $(date +%s) ))
    if [ "$left" -lt 15 ]; then
      echo "($part: not run, the check's time was spent)" | tee -a "$out/console.txt"
      continue
    fi
    limit=$(( left < 240 ? left : 240 ))
    rc=0
    # The GPU-filling batches run under burn's default autotune: the layers whose products
    # needed more than 65,535 workgroups (H200, 2026-11-26) now run in slices.
    env=()
    run_part=$part
    part_out=$out
    if [ "$part" = warm ]; then
      # The neurokin part again, in a new process, on what the first run left in the cache.
      run_part=neurokin
      part_out=$out/warm
      mkdir -p "$part_out"
      echo "(warm: the neurokin part again, its autotune results and kernels cached)" >>"$out/console.txt"
    fi
    if [ "$part" = profile ]; then
      # The counts' NeuroKin steps again under cubecl's profiler: each kernel's time.
      run_part=counts
      env=(CUBECL_DEBUG_OPTION=profile CUBECL_DEBUG_LOG=/tmp/cubecl_profile.log)
      echo "(profile: the counts part under CUBECL_DEBUG_OPTION=profile; kernel times in profile.txt)" >>"$out/console.txt"
    fi
    env "${env[@]}" timeout "$limit" "$PACK/gpu_check" --torch python3 --bench-dir "$PACK/bench" \
      --out "$part_out" --parts "$run_part" "$@" 2>"$out/$part.stderr" || rc=$?
    if [ "$part" = profile ] && [ -f /tmp/cubecl_profile.log ]; then
      grep '^|' /tmp/cubecl_profile.log | sed 's/  */ /g' | tail -c 8000000 >"$out/profile.txt" || true
    fi
    if [ "$rc" -ne 0 ]; then
      echo "($part: stopped, exit $rc, limit $limit s; last lines of its stderr:)" | tee -a "$out/console.txt"
      tail -c 2000 "$out/$part.stderr" | tee -a "$out/console.txt"
    fi
    [ -s "$out/$part.stderr" ] || rm -f "$out/$part.stderr"
  done
  ;;
*)
  echo "usage: scripts/gpu_check.sh pack | run [gpu_check arguments]" >&2
  exit 2
  ;;
esac
