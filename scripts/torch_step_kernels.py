#!/usr/bin/env python3
"""The kernels PyTorch launches for one NeuroKin training step, counted by torch.profiler.

The GPU check's `counts` part (`gpu_check --parts counts --python PY`) runs it beside its count
of our own step and writes both, so the two counts come from the same GPU in the same sitting.
The step is the one `torch_gpu_reference.py` times: the papers' NeuroKin (`torch_reference.py`,
in the folder given by --bench), BCE, Adam at 1e-3, eager fp32, at the paper's batch 32 and at
256. It is counted with Adam as PyTorch runs it by default (`foreach`, the multi-tensor path) and
with `fused=True`.

On a CUDA GPU it counts the device kernels of the profiled steps (CUDA activity), and separately
their memory copies and fills. On a machine without one, it counts the aten operators instead,
which is a dry run of the script and not a launch count; the device column says which it counted.

Prints one line per count, `model batch optimizer kernels_per_step memory_ops_per_step device`.
"""
import argparse
import importlib.util
import os
import sys

import torch
import torch.nn as nn
from torch.autograd import DeviceType
from torch.profiler import ProfilerActivity, profile


def load_reference(bench):
    path = os.path.join(bench, "torch_reference.py")
    spec = importlib.util.spec_from_file_location("ref", path)
    ref = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ref)
    return ref


def sync(dev):
    if dev == "cuda":
        torch.cuda.synchronize()


def under_aten(event):
    """Whether an aten operator calls this one (only the outermost is counted on a CPU)."""
    parent = event.cpu_parent
    while parent is not None:
        if parent.name.startswith("aten::"):
            return True
        parent = parent.cpu_parent
    return False


def count(ref, dev, batch, fused, steps):
    """Kernels and memory operations a step, over `steps` steps after three of warm-up."""
    torch.manual_seed(0)
    cls, res, _, _ = ref.MODELS["neurokin"]
    model = cls().to(dev).train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3, fused=fused)
    loss = nn.BCELoss()
    q = torch.randn(batch, 4, device=dev) * 30
    y = (torch.rand(batch, 1, res, res, device=dev) < 0.1).float()

    def step():
        opt.zero_grad(set_to_none=True)
        loss(model(q), y).backward()
        opt.step()

    for _ in range(3):
        step()
    sync(dev)
    activities = [ProfilerActivity.CUDA] if dev == "cuda" else [ProfilerActivity.CPU]
    with profile(activities=activities) as prof:
        for _ in range(steps):
            step()
        sync(dev)
    kernels = memory = 0
    for e in prof.events():
        if dev == "cuda":
            if e.device_type != DeviceType.CUDA:
                continue
            if e.name.startswith(("Memcpy", "Memset")):
                memory += 1
            else:
                kernels += 1
        elif e.name.startswith("aten::") and not under_aten(e):
            kernels += 1
    return kernels / steps, memory / steps


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bench", required=True, help="the folder of torch_reference.py")
    ap.add_argument("--steps", type=int, default=10, help="steps profiled (after 3 of warm-up)")
    ap.add_argument("--batches", default="32,256", help="batches, comma-separated")
    a = ap.parse_args()
    dev = "cuda" if torch.cuda.is_available() else "cpu"
    name = torch.cuda.get_device_name(0) if dev == "cuda" else "cpu (aten operators, not kernels)"
    print(f"torch {torch.__version__} on {name}", file=sys.stderr)
    if dev == "cuda":
        torch.backends.cuda.matmul.allow_tf32 = False
        torch.backends.cudnn.allow_tf32 = False
    ref = load_reference(a.bench)
    device = "cuda" if dev == "cuda" else "cpu_aten"
    for batch in [int(b) for b in a.batches.split(",")]:
        for optimizer, fused in [("adam_foreach", False), ("adam_fused", True)]:
            k, m = count(ref, dev, batch, fused, a.steps)
            print(f"NeuroKin {batch} {optimizer} {k:.1f} {m:.1f} {device}", flush=True)


if __name__ == "__main__":
    main()
