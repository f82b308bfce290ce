#!/usr/bin/env python3
"""The cuda kernels held to budgets, with no GPU (docs/cuda.md, "Budgets"): compiles src/cuda/convolve.cu
for one architecture with `ptxas -v` (nvcc) and line information, reads every kernel's registers and
spill stores, disassembles the code (nvdisasm: next to nvcc, on PATH, or PyPI's nvidia-cuda-nvdisasm
wheel in BUILD_DIR/sass-venv, made on first use) and finds each kernel's pixel loop, the innermost loop
that loads from global memory and runs src/kernel/pixel.glsl's or interpolate.glsl's code. Checks them
against tests/cuda/kernel_budgets.txt: registers, spill bytes and the pixel loop's instructions (one
lane-pixel each) at most their budgets, and no local memory (a spill) in the pixel loop. Every kernel
must have a budget line and every budget line a kernel, so that a new variant or a renamed one is
budgeted on purpose.

Usage: kernel_budgets.py NVCC SOURCE_DIR BUILD_DIR [--arch sm_90] [--nvdisasm PATH] [--report FILE]
Exit status 0 when every kernel is within its budget, 1 otherwise (the table says which), 2 when the
compilation itself fails, 77 when the registers are within budget but no disassembler could be had
(PyPI unreachable; with PISCO_REQUIRE_PEERS=1 that is a failure instead)."""
import argparse
import collections
import re
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "python"))
import python_env  # noqa: E402  (tests/python/python_env.py: the venv maker the python tests use)

SKIP = 77
NVDISASM_WHEEL = {"nvidia-cuda-nvdisasm==13.*": "nvidia.cu13"}


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


def compile_report(nvcc, source_dir, build_dir, arch, cubin):
    flags = ["-O3", "-DNDEBUG", "-std=c++17", "-DPISCO_HAVE_CUDA", '-DPISCO_CUDA_ARCHITECTURES="%s"' % arch[3:],
             "-I" + str(source_dir / "include"), "-I" + str(build_dir / "include"), "-I" + str(source_dir / "src"),
             "-arch=" + arch, "-cubin", "-lineinfo", "-Xptxas", "-v", "-o", str(cubin),
             str(source_dir / "src" / "cuda" / "convolve.cu")]
    run = subprocess.run([nvcc] + flags, capture_output=True, text=True)
    if run.returncode != 0:
        sys.stderr.write(run.stdout + run.stderr)
        sys.stderr.write("kernel_budgets: nvcc failed to compile src/cuda/convolve.cu for %s\n" % arch)
        sys.exit(2)
    return run.stdout + run.stderr


def find_nvdisasm(nvcc, build_dir, given):
    """(path, None) or (None, the reason there is none)."""
    if given:
        return given, None
    beside = Path(nvcc).resolve().parent / "nvdisasm"
    if beside.is_file():
        return str(beside), None
    on_path = shutil.which("nvdisasm")
    if on_path:
        return on_path, None
    venv = build_dir / "sass-venv"
    try:
        python_env.ensure_venv(str(venv), NVDISASM_WHEEL, log=lambda m: print("sass-venv: " + m, flush=True))
    except python_env.Unavailable as exc:
        return None, str(exc)
    for found in sorted(venv.glob("lib/python*/site-packages/nvidia/cu13/bin/nvdisasm")):
        return str(found), None
    return None, "the nvidia-cuda-nvdisasm wheel in %s holds no nvdisasm" % venv


def pixel_loops(sass):
    """{mangled name: (instructions, local memory instructions)} of each kernel's pixel loop (None when
    none is found): the innermost loop (a branch back to a label) holding a global load and code from
    pixel.glsl or interpolate.glsl, as nvdisasm -gi prints it (each instruction after the source lines
    of its inlining chain)."""
    loops, name, body = {}, None, []

    def close():
        if name is None:
            return
        best = None
        code = [x for x in body if not isinstance(x, str)]
        index, k = {}, 0  # a label's position among the instructions
        for item in body:
            if isinstance(item, str):
                index[item] = k
            else:
                k += 1
        for i, (text, chain) in enumerate(code):
            m = re.search(r"BRA\s+`?\(?(\.L_x_\d+)", text)
            if not m or m.group(1) not in index or index[m.group(1)] > i:
                continue
            loop = code[index[m.group(1)]:i + 1]
            pixel = any("pixel.glsl" in c or "interpolate.glsl" in c for _, c in loop)
            loads = any(re.search(r"\bLDG\b", t) for t, _ in loop)
            if pixel and loads and (best is None or len(loop) < len(best)):
                best = loop
        if best is None:
            loops[name] = None
            return
        ops = collections.Counter(re.sub(r"^@!?U?P\w+\s+", "", t).split()[0].split(".")[0] for t, _ in best)
        loops[name] = (len(best), ops["LDL"] + ops["STL"])

    chain = []
    fresh = False
    for line in sass.splitlines():
        m = re.match(r"^\.text\.(\S+):", line)
        if m:
            close()
            name, body, chain, fresh = m.group(1), [], [], False
            continue
        if name is None:
            continue
        m = re.match(r'\s*//## File "([^"]+)"', line)
        if m:
            if not fresh:
                chain, fresh = [], True
            chain.append(m.group(1).rsplit("/", 1)[-1])
            continue
        m = re.match(r"^(\.L_x_\d+):", line)
        if m:
            body.append(m.group(1))
            continue
        m = re.match(r"\s*/\*[0-9a-f]{4,}\*/\s+(.*?)\s*;?\s*$", line)
        if m:
            fresh = False
            body.append((m.group(1), " ".join(chain)))
    close()
    return loops


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
    ap.add_argument("--nvdisasm")
    ap.add_argument("--report", type=Path)
    a = ap.parse_args()
    budgets_path = a.budgets or a.source_dir / "tests" / "cuda" / "kernel_budgets.txt"
    budgets = {}
    for n, line in enumerate(budgets_path.read_text().splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.split()
        if len(fields) != 4:
            sys.exit("%s:%d: expected 'KERNEL MAX_REGISTERS MAX_SPILL_BYTES MAX_LOOP_INSTRUCTIONS', got %r"
                     % (budgets_path, n, line))
        budgets[fields[0]] = tuple(int(f) for f in fields[1:])
    work = a.build_dir / "cuda-budgets"
    work.mkdir(parents=True, exist_ok=True)
    cubin = work / ("convolve_%s.cubin" % a.arch)
    report = compile_report(a.nvcc, a.source_dir, a.build_dir, a.arch, cubin)
    if a.report:
        a.report.write_text(report)
    kernels = parse(report)
    if not kernels:
        sys.stderr.write(report)
        sys.exit("kernel_budgets: ptxas reported no entry function")
    nvdisasm, why_not = find_nvdisasm(a.nvcc, a.build_dir, a.nvdisasm)
    loops = {}
    if nvdisasm:
        run = subprocess.run([nvdisasm, "-gi", str(cubin)], capture_output=True, text=True)
        if run.returncode != 0:
            sys.stderr.write(run.stderr)
            sys.exit("kernel_budgets: %s failed on %s" % (nvdisasm, cubin))
        (work / ("convolve_%s.sass" % a.arch)).write_text(run.stdout)
        loops = pixel_loops(run.stdout)
    names = dict(zip(kernels, (short_name(d) for d in demangle(list(kernels)))))
    failures = []
    print("%-52s %9s %7s %13s %10s %11s %7s" % ("kernel (%s)" % a.arch, "registers", "budget", "spill stores",
                                                 "occupancy", "loop instr", "budget"))
    seen = set()
    for mangled, (regs, spill) in sorted(kernels.items(), key=lambda kv: names[kv[0]]):
        name = names[mangled]
        seen.add(name)
        budget = budgets.get(name)
        loop = loops.get(mangled)
        print("%-52s %9d %7s %10d B %9.1f%% %11s %7s%s" % (
            name, regs, budget[0] if budget else "-", spill, occupancy(regs),
            ("%d" % loop[0] + (" +%d local" % loop[1] if loop[1] else "")) if loop else "-",
            budget[2] if budget else "-", "" if budget else "   <- no budget line"))
        if budget is None:
            failures.append("%s: no line in %s" % (name, budgets_path.name))
            continue
        if regs > budget[0]:
            failures.append("%s: %d registers, over its budget of %d" % (name, regs, budget[0]))
        if spill > budget[1]:
            failures.append("%s: %d bytes of spill stores, over its budget of %d" % (name, spill, budget[1]))
        if nvdisasm:
            if loop is None:
                failures.append("%s: no pixel loop found in its code" % name)
            else:
                if loop[0] > budget[2]:
                    failures.append("%s: %d instructions in the pixel loop, over its budget of %d"
                                    % (name, loop[0], budget[2]))
                if loop[1]:
                    failures.append("%s: %d local-memory instructions (spills) in the pixel loop" % (name, loop[1]))
    for name in sorted(set(budgets) - seen):
        failures.append("%s: budgeted in %s but no such kernel was compiled" % (name, budgets_path.name))
    if not nvdisasm and python_env.REQUIRED:
        failures.append("no nvdisasm for the pixel loops' budgets (PISCO_REQUIRE_PEERS=1): " + why_not)
    if failures:
        print("\n".join(["", "over budget or unbudgeted:"] + failures))
        return 1
    if not nvdisasm:
        print("%d kernels within their register and spill budgets; SKIPPED the pixel loops': %s"
              % (len(kernels), why_not))
        return SKIP
    print("%d kernels within their budgets (%s)" % (len(kernels), nvdisasm))
    return 0


if __name__ == "__main__":
    sys.exit(main())
