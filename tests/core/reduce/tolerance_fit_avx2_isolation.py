#!/usr/bin/env python3
"""The error-bounded fit's AVX2 build (core/CMakeLists.txt) keeps its AVX2 instructions to itself.

A processor without AVX2 never calls into that build (FitWithinTolerance() chooses the baseline
one), but it still runs what the object file holds besides the build's own functions: the
inline functions and templates of the libraries it uses, of which the linker keeps a single copy
for the whole program, possibly this one, and its static initializer, which runs before main().
Read from the object file itself with binutils' disassembler (objdump), not from our sources:
  - no VEX- or EVEX-encoded instruction (every such mnemonic starts with 'v': vmovsd, vaddpd,
    vzeroupper ...) in a function whose name does not involve tempokey::core::tolerance_fit_avx2
    (a template of a library over one of its types is the build's own: no other object file
    has it);
  - the static initializer calls nothing of that namespace;
  - and the build's own functions do hold AVX instructions (ymm registers), so the check is of an
    AVX2 build at all.
Usage: tolerance_fit_avx2_isolation.py OBJECT
"""
import re
import subprocess
import sys

OWN = "tempokey::core::tolerance_fit_avx2::"
FUNCTION = re.compile(r"^[0-9a-f]+ <(.*)>:$")
INSTRUCTION = re.compile(r"^\s+[0-9a-f]+:\s+([a-z][a-z0-9.]*)\b(.*)$")
RELOCATION = re.compile(r"^\s+[0-9a-f]+: R_X86_64_\w+\s+(\S+)")


def main(path):
    listing = subprocess.run(["objdump", "-dr", "--no-show-raw-insn", "--demangle", path],
                             check=True, capture_output=True, text=True).stdout
    name = None
    foreign_vex = {}   # function outside the build -> its first VEX instruction
    own_ymm = 0
    init_calls = []
    for line in listing.splitlines():
        m = FUNCTION.match(line)
        if m:
            name = m.group(1)
            continue
        if name is None:
            continue
        m = RELOCATION.match(line)
        if m and name.startswith("_GLOBAL__sub_I"):
            init_calls.append(m.group(1))
            continue
        m = INSTRUCTION.match(line)
        if not m:
            continue
        mnemonic, operands = m.groups()
        if OWN in name:
            own_ymm += "%ymm" in operands
        elif mnemonic.startswith("v"):
            foreign_vex.setdefault(name, f"{mnemonic}{operands}")
    failures = [f"{function}: {instruction.strip()}" for function, instruction in
                sorted(foreign_vex.items())]
    failures += [f"the static initializer calls {target}" for target in init_calls
                 if "tolerance_fit_avx2" in target and not target.startswith(".")]
    if own_ymm == 0:
        failures.append(f"no instruction of {OWN} uses a ymm register: not an AVX2 build")
    if failures:
        print(f"{path}:")
        for failure in failures:
            print(f"  {failure}")
        return 1
    print(f"{path}: AVX2 in {OWN} only ({own_ymm} instructions on ymm registers); "
          f"static initializer calls: {', '.join(init_calls) or 'none'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
