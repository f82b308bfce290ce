#!/usr/bin/env python3
"""The cuda kernels' registers and spills held to budgets, with no GPU: compiles src/cuda/convolve.cu for
one architecture with `ptxas -v` (nvcc), reads every kernel's registers and spill stores, and checks
them against tests/cuda/kernel_budgets.txt (docs/cuda.md, "Budgets"). Every kernel must have a budget
line and every budget line a kernel, so that a new variant or a renamed one is budgeted on purpose.

Usage: kernel_budgets.py NVCC SOURCE_DIR BUILD_DIR [--arch sm_90] [--report FILE]
Exit status 0 when every kernel is within its budget, 1 otherwise (the table says which), 2 when the
compilation itself fails."""
import argparse
import re
import subprocess
import sys
from pathlib import Path


def demangle(names):
    out = subprocess.run(["c++filt"], input="\n".join(names), capture_output=True, text=True, check=True)
    return out.stdout.splitlines()


def short_name(demangled):
    """'void pisco::detail::cuda::(anonymous namespace)::convolve_kernel<false, true, ...>(args)' ->
    'convolve_kernel<false,true,...>'."""
    text = demangled.replace("(anonymous namespace)::", "")
    text = text.split("(", 1)[0]
    if text.startswith("void "):
        text = text[len("void "):]
    bracket = text.find("<")
    scope = text.rfind("::", 0, bracket if bracket >= 0 else len(text))
    return text[scope + 2:].replace(" ", "") if scope >= 0 else text.replace(" ", "")


def occupancy(registers, block_threads=256, sm_registers=65536, sm_warps=64):
    """Percent of an SM's warps resident, by registers alone: registers are allocated per warp in units
    of 256 (8 a thread), blocks of block_threads (convolve.cu's 8 warps)."""
    per_warp = -(-registers * 32 // 256) * 256
    blocks = sm_registers // (per_warp * (block_threads // 32))
    return 100.0 * min(sm_warps, blocks * block_threads // 32) / sm_warps


def compile_report(nvcc, source_dir, build_dir, arch):
    flags = ["-O3", "-DNDEBUG", "-std=c++17", "-DPISCO_HAVE_CUDA", '-DPISCO_CUDA_ARCHITECTURES="%s"' % arch[3:],
             "-I" + str(source_dir / "include"), "-I" + str(build_dir / "include"), "-I" + str(source_dir / "src"),
             "-I" + str(source_dir / "shaders"), "-arch=" + arch, "-cubin", "-Xptxas", "-v", "-o", "/dev/null",
             str(source_dir / "src" / "cuda" / "convolve.cu")]
    run = subprocess.run([nvcc] + flags, capture_output=True, text=True)
    if run.returncode != 0:
        sys.stderr.write(run.stdout + run.stderr)
        sys.stderr.write("kernel_budgets: nvcc failed to compile src/cuda/convolve.cu for %s\n" % arch)
        sys.exit(2)
    return run.stdout + run.stderr


def parse(report):
    """{mangled name: (registers, spill store bytes)} of every entry function."""
    kernels, current, properties_of, spills = {}, None, None, 0
    for line in report.splitlines():
        m = re.search(r"Compiling entry function '([^']+)'", line)
        if m:
            current, spills = m.group(1), 0
            continue
        m = re.search(r"Function properties for (\S+)", line)
        if m:
            properties_of = m.group(1)
            continue
        m = re.search(r"(\d+) bytes spill stores", line)
        if m and current is not None and properties_of == current:
            spills = int(m.group(1))
        m = re.search(r"Used (\d+) registers", line)
        if m and current is not None:
            kernels[current] = (int(m.group(1)), spills)
            current = None
    return kernels


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("nvcc")
    ap.add_argument("source_dir", type=Path)
    ap.add_argument("build_dir", type=Path)
    ap.add_argument("--arch", default="sm_90")
    ap.add_argument("--budgets", type=Path)
    ap.add_argument("--report", type=Path)
    a = ap.parse_args()
    budgets_path = a.budgets or a.source_dir / "tests" / "cuda" / "kernel_budgets.txt"
    budgets = {}
    for n, line in enumerate(budgets_path.read_text().splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.split()
        if len(fields) != 3:
            sys.exit("%s:%d: expected 'KERNEL MAX_REGISTERS MAX_SPILL_BYTES', got %r" % (budgets_path, n, line))
        budgets[fields[0]] = (int(fields[1]), int(fields[2]))
    report = compile_report(a.nvcc, a.source_dir, a.build_dir, a.arch)
    if a.report:
        a.report.write_text(report)
    kernels = parse(report)
    if not kernels:
        sys.stderr.write(report)
        sys.exit("kernel_budgets: ptxas reported no entry function")
    names = dict(zip(kernels, (short_name(d) for d in demangle(list(kernels)))))
    failures = []
    print("%-60s %9s %7s %13s %10s" % ("kernel (%s)" % a.arch, "registers", "budget", "spill stores", "occupancy"))
    seen = set()
    for mangled, (regs, spill) in sorted(kernels.items(), key=lambda kv: names[kv[0]]):
        name = names[mangled]
        seen.add(name)
        budget = budgets.get(name)
        print("%-60s %9d %7s %10d B %9.1f%%%s" % (name, regs, budget[0] if budget else "-", spill, occupancy(regs),
                                                  "" if budget else "   <- no budget line"))
        if budget is None:
            failures.append("%s: no line in %s" % (name, budgets_path.name))
        else:
            if regs > budget[0]:
                failures.append("%s: %d registers, over its budget of %d" % (name, regs, budget[0]))
            if spill > budget[1]:
                failures.append("%s: %d bytes of spill stores, over its budget of %d" % (name, spill, budget[1]))
    for name in sorted(set(budgets) - seen):
        failures.append("%s: budgeted in %s but no such kernel was compiled" % (name, budgets_path.name))
    if failures:
        print("\n".join(["", "over budget or unbudgeted:"] + failures))
        return 1
    print("%d kernels within their budgets" % len(kernels))
    return 0


if __name__ == "__main__":
    sys.exit(main())
