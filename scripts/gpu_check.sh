#!/usr/bin/env bash
# The GPU check (experiments/gpu_check.rs), for a GPU machine with no Rust toolchain and no
# registry (../shared/notes/gpu.md).
#
#   scripts/gpu_check.sh pack          # here, on a CPU machine with Rust (scripts/build_cuda.sh:
#                                      # ~30 min clean, minutes after; target/cuda/)
#   scripts/gpu_check.sh run [ARGS]    # there, from the repository root, target/gpu_check and
#                                      # target/gpu_check_N carried (a call each, then run)
#
# `pack` builds one binary with both GPU backends, burn's CUDA (`--features cuda`) and wgpu
# (WGSL through naga), stripped and compressed, into target/gpu_check/ with Debian's Vulkan
# loader and the GL dispatch libraries the NVIDIA driver's Vulkan library links (the GPU
# machines had neither) and PyTorch's reference scripts (git-ignored; the binary in 20 MiB
# parts, a folder each, as the tree is ~35 MB of the 64 MiB a call carries). `run` measures both backends in one call,
# the most valuable parts first, in at most GPU_CHECK_SECONDS (default 480) of the machine:
#   cuda: decoders neurokin peak profile (the counts part under cubecl's profiler, then each
#   kernel of the step against its bound: kernels.csv) precision;  wgpu: decoders neurokin peak
#   profile; then cuda's counts without the profiler,
#   equivalence, the CPU at 2 and 16 threads, k3dgs, fill, split, as time allows;
#   and last a summary of every ratio against PyTorch and which backend is faster.
# Output in $OUT/gpu/<GPU name>/{cuda,wgpu}/ (or reports/gpu/<GPU name>/ without $OUT); ARGS go
# to the binary (e.g. --threads 2,16); GPU_CHECK_PLAN overrides the plan ("cuda:decoders
# wgpu:decoders ..."). cubecl keeps its autotune results in target/environment/ under a fresh
# CUBECL_ENVIRONMENT, so the first neurokin run of a backend tunes from nothing.
set -euo pipefail
cd "$(dirname "$0")/.."
PACK=${GPU_CHECK_PACK:-target/gpu_check}

case "${1:-}" in
pack)
  FEATURES=wgpu,cuda scripts/build_cuda.sh --bin gpu_check
  dir=target/gpu_check
  rm -rf "$dir" "$dir"_[0-9] && mkdir -p "$dir/debs" "$dir/bench"
  strip -o "$dir/gpu_check" target/cuda/release/gpu_check
  xz -6 -T2 "$dir/gpu_check"
  # ~41 MB compressed (CUDA's LLVM inside): with the ~35 MB tree over the 64 MiB a call carries,
  # so in parts of 20 MiB, one folder each (target/gpu_check, target/gpu_check_1, ...), carried
  # a call each; `run` joins them.
  (cd "$dir" && split -b 20M -d -a 2 gpu_check.xz gpu_check.xz.part. && rm gpu_check.xz)
  n=0
  for part in "$dir"/gpu_check.xz.part.*; do
    if [ "$n" -gt 0 ]; then mkdir -p "${dir}_$n" && mv "$part" "${dir}_$n/"; fi
    n=$((n + 1))
  done
  echo "$n" >"$dir/parts"
  (cd "$dir/debs" && apt-get download libvulkan1 libglvnd0 libegl1 libgl1 libglx0 libopengl0 libgles2 \
    libx11-6 libxcb1 libxau6 libxdmcp6 libbsd0 libmd0 libxext6 >/dev/null)
  cp ../shared/bench/torch_reference.py ../shared/bench/torch_gpu_reference.py \
    scripts/torch_step_kernels.py "$dir/bench/"
  du -sh "$dir" "$dir"_[0-9] 2>/dev/null || true
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
  # libdevice (exp, log, tanh in PTX): CUDA's, where the machine has it.
  libdevice=$(ls /usr/local/cuda*/nvvm/libdevice/libdevice*.bc 2>/dev/null | head -1 || true)
  [ -z "$libdevice" ] || export CUDA_PATH=${libdevice%/nvvm/libdevice/*}
  # The binary's parts, one folder each (`pack`), joined in order of their numbers.
  parts=$(ls "$PACK"*/gpu_check.xz.part.* 2>/dev/null | sort -t. -k4 || true)
  if [ "$(echo "$parts" | grep -c .)" != "$(cat "$PACK/parts" 2>/dev/null)" ]; then
    echo "error: the pack's parts are not all here (carry $PACK and each ${PACK}_N that pack made)" >&2
    exit 1
  fi
  cat $parts | xz -d >"$PACK/gpu_check" && chmod +x "$PACK/gpu_check"
  name=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 | tr -c 'A-Za-z0-9\n' '_' || true)
  name=${name:-unknown_gpu}
  root="${OUT:-reports}/gpu/$name"
  plan=${GPU_CHECK_PLAN:-"cuda:decoders cuda:neurokin cuda:peak cuda:profile cuda:precision wgpu:decoders wgpu:neurokin wgpu:peak wgpu:profile cuda:counts cuda:equivalence cuda:cpu cuda:k3dgs cuda:fill cuda:split"}
  mkdir -p "$root"
  export CUBECL_ENVIRONMENT="gpu_check_$(date +%s)"
  nvidia-smi > "$root/nvidia-smi.txt" 2>&1 || true
  # One process a part, each under its own limit (at most 240 s, and what is left of the run's
  # less the summary's 10 s), so a part that hangs or aborts costs only itself.
  deadline=$(( $(date +%s) + ${GPU_CHECK_SECONDS:-480} - 10 ))
  for step in $plan; do
    device=${step%%:*}
    part=${step#*:}
    out=$root/$device
    mkdir -p "$out"
    left=$(( deadline - $(date +%s) ))
    if [ "$left" -lt 15 ]; then
      echo "($device $part: not run, the check's time was spent)" | tee -a "$out/console.txt"
      continue
    fi
    limit=$(( left < 240 ? left : 240 ))
    # PyTorch's side is the same for both backends: measured once, kept in torch_gpu.txt.
    for other in "$root"/*/torch_gpu.txt; do
      [ -f "$other" ] && [ ! -f "$out/torch_gpu.txt" ] && cp "$other" "$out/"
    done
    env=()
    run_part=$part
    if [ "$part" = profile ]; then
      # The counts' NeuroKin steps again under cubecl's profiler: each kernel's time.
      run_part=counts
      env=(CUBECL_DEBUG_OPTION=profile CUBECL_DEBUG_LOG=/tmp/cubecl_profile.log)
      echo "(profile: the counts part under CUBECL_DEBUG_OPTION=profile; kernel times in profile.txt)" >>"$out/console.txt"
    fi
    # The CPU at 2 and 16 threads only (2, 4, 8, 16 would not fit the sitting).
    extra=()
    if [ "$part" = cpu ]; then extra=(--threads 2,16); fi
    rc=0
    env "${env[@]}" timeout "$limit" "$PACK/gpu_check" --device "$device" --torch python3 --bench-dir "$PACK/bench" \
      --out "$out" --parts "$run_part" "${extra[@]}" "$@" 2>"$out/$part.stderr" || rc=$?
    if [ "$part" = profile ] && [ -f /tmp/cubecl_profile.log ]; then
      # Each kernel of the profiled step against its bound (kernels.csv), then the profile kept
      # compressed.
      grep '^|' /tmp/cubecl_profile.log | sed 's/  */ /g' | tail -c 8000000 >"$out/profile.txt" || true
      timeout 60 "$PACK/gpu_check" --device "$device" --out "$out" --parts roofline 2>>"$out/$part.stderr" || true
      xz -6f "$out/profile.txt" || true
      rm -f /tmp/cubecl_profile.log
    fi
    if [ "$rc" -ne 0 ]; then
      echo "($device $part: stopped, exit $rc, limit $limit s; last lines of its stderr:)" | tee -a "$out/console.txt"
      tail -c 2000 "$out/$part.stderr" | tee -a "$out/console.txt"
    fi
    [ -s "$out/$part.stderr" ] || rm -f "$out/$part.stderr"
  done
  "$PACK/gpu_check" --out "$root" --parts summary --device cuda || true
  ;;
*)
  echo "usage: scripts/gpu_check.sh pack | run [gpu_check arguments]" >&2
  exit 2
  ;;
esac
