#!/usr/bin/env python3
"""The error-bounded fit's AVX2 build (core/CMakeLists.txt) keeps its AVX2 instructions to itself.

A processor without AVX2 never calls into that build (FitWithinTolerance() chooses the baseline
one), but it still runs what the object file holds besides the build's own functions: the
inline functions and templates of the libraries it uses, of which the linker keeps a single copy
for the whole program, possibly this one (ar puts this object first in libtempokey_core.a), and
its static initializers, which run before main(). Read from the object file itself with
binutils' disassembler (objdump), not from our sources:
  - no instruction that the avx2 target enables (VEX- and EVEX-encoded ones, whose mnemonics
    all start with 'v': vmovsd, vaddpd, vzeroupper ...; popcnt, crc32) in a function whose name
    does not involve tempokey::core::tolerance_fit_avx2 (a template of a library over one of its
    types is the build's own: no other object file has it), nor in a resolver of clones;
  - no function reachable from a static initializer (the functions .init_array names, then every
    call and jump they make, by relocation or by address, transitively) is the build's own or
    holds such an instruction;
  - and the build's own functions do hold AVX instructions (ymm registers), so the check is of an
    AVX2 build at all.
Usage: tolerance_fit_avx2_isolation.py OBJECT
"""
import re
import subprocess
import sys

OWN = "tempokey::core::tolerance_fit_avx2::"
FUNCTION = re.compile(r"^([0-9a-f]+) <(.*)>:$")
INSTRUCTION = re.compile(r"^\s+([0-9a-f]+):\s+([a-z][a-z0-9.]*)\b(.*)$")
RELOCATION = re.compile(r"^\s+[0-9a-f]+: R_X86_64_\w+\s+(\S+?)(?:[-+]0x[0-9a-f]+)?$")
# A call or jump to an address in the same section: "call 1a0 <name+0x10>".
BRANCH_TARGET = re.compile(r"<([^>+]+)(?:\+0x[0-9a-f]+)?>")


def is_wide(mnemonic):
    return mnemonic.startswith("v") or mnemonic in ("popcnt", "crc32") or \
        mnemonic.startswith("crc32")


def is_own(name):
    return OWN in name and "[clone .resolver]" not in name


def main(path):
    listing = subprocess.run(["objdump", "-dr", "--no-show-raw-insn", "--demangle", path],
                             check=True, capture_output=True, text=True).stdout
    functions = {}   # name -> {"wide": first wide instruction or None, "calls": set()}
    name = None
    last_was_branch = False
    for line in listing.splitlines():
        m = FUNCTION.match(line)
        if m:
            name = m.group(2)
            functions.setdefault(name, {"wide": None, "calls": set(), "ymm": 0})
            continue
        if name is None:
            continue
        entry = functions[name]
        m = RELOCATION.match(line)
        if m:
            if last_was_branch:
                entry["calls"].add(m.group(1))
            continue
        m = INSTRUCTION.match(line)
        if not m:
            continue
        _, mnemonic, operands = m.groups()
        last_was_branch = mnemonic in ("call", "jmp") or mnemonic.startswith("j")
        if last_was_branch:
            t = BRANCH_TARGET.search(operands)
            if t:
                entry["calls"].add(t.group(1))
        entry["ymm"] += "%ymm" in operands
        if is_wide(mnemonic) and entry["wide"] is None:
            entry["wide"] = f"{mnemonic}{operands}".strip()

    # The static initializers: the functions the .init_array section's relocations name.
    relocations = subprocess.run(["objdump", "-r", "-j", ".init_array", "--demangle", path],
                                 capture_output=True, text=True).stdout
    roots = []
    for line in relocations.splitlines():
        m = re.match(r"^[0-9a-f]+\s+R_X86_64_\w+\s+(\S+?)(?:[-+]0x[0-9a-f]+)?$", line)
        if m:
            roots.append(m.group(1))
    # A relocation against a section (".text.startup+0x0") names no function: its functions are
    # the _GLOBAL__sub_I ones, which GCC puts there.
    if any(r.startswith(".") for r in roots):
        roots = [r for r in roots if not r.startswith(".")] + \
                [f for f in functions if f.startswith("_GLOBAL__sub_I")]

    failures = []
    for function, entry in sorted(functions.items()):
        if not is_own(function) and entry["wide"] is not None:
            failures.append(f"{function}: {entry['wide']}")
    seen = set()
    todo = list(roots)
    while todo:
        f = todo.pop()
        if f in seen or f not in functions:
            continue
        seen.add(f)
        # (A wide function outside the build is a failure already, reached or not.)
        if is_own(f):
            failures.append(f"a static initializer reaches {f}")
        todo.extend(functions[f]["calls"])
    own_ymm = sum(e["ymm"] for f, e in functions.items() if is_own(f))
    if own_ymm == 0:
        failures.append(f"no instruction of {OWN} uses a ymm register: not an AVX2 build")
    if not roots:
        failures.append("no static initializer found: the check of them would see nothing")
    if failures:
        print(f"{path}:")
        for failure in failures:
            print(f"  {failure}")
        return 1
    print(f"{path}: AVX2 in {OWN} only ({own_ymm} instructions on ymm registers); "
          f"static initializers {', '.join(roots)} reach {len(seen)} functions of this object, "
          f"none of them the build's own or wide")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
