"""Reading XLA's optimised HLO text: which instructions run inside one-kernel loops ("small calls") on XLA:CPU.

`xla_options.CPU_XLA_FLAGS` lets XLA:CPU compile a small while loop as one kernel, unless the loop holds a scatter, a
dot, a custom call or a collective; tests/test_one_kernel.py and benchmarks/kernels.py read a compiled chunk here.
"""

from __future__ import annotations

import collections
import re


def computations(hlo: str) -> dict[str, list[str]]:
    """The instruction lines of each computation of an HLO text module, by name."""
    found, current = {}, None
    for line in hlo.splitlines():
        head = re.match(r"^(?:ENTRY )?%(\S+) \(.*\{$", line)
        if head:
            current = found.setdefault(head.group(1), [])
        elif line.strip() == "}":
            current = None
        elif current is not None:
            current.append(line)
    return found


def called(lines: list[str]) -> set[str]:
    """The computations that these instructions call, run as loop bodies or fuse."""
    return {m for line in lines for m in re.findall(r"(?:to_apply|body|condition|calls)=%([\w.\-]+)", line)}


def in_small_calls(hlo: str) -> set[str]:
    """The computations that run inside a one-kernel call, directly or through the ones they call."""
    comps = computations(hlo)
    todo = [c for lines in comps.values() for line in lines if "xla_cpu_small_call" in line for c in called([line])]
    inside = set()
    while todo:
        name = todo.pop()
        if name not in inside:
            inside.add(name)
            todo.extend(called(comps.get(name, [])))
    return inside


def count(hlo: str, op: str) -> tuple[int, int]:
    """(instructions `op` inside one-kernel calls, instructions `op` elsewhere) of an optimised HLO module."""
    comps, inside = computations(hlo), in_small_calls(hlo)
    found = {True: 0, False: 0}
    for name, lines in comps.items():
        found[name in inside] += sum(f" {op}(" in line for line in lines)
    return found[True], found[False]


def opcodes(hlo: str, inside: bool = True) -> collections.Counter:
    """Instructions by opcode, inside one-kernel calls (or outside them), parameters and tuples aside."""
    comps, small = computations(hlo), in_small_calls(hlo)
    kinds = collections.Counter()
    for name, lines in comps.items():
        if (name in small) != inside:
            continue
        for line in lines:
            op = re.search(r"=\s*\S+\s+([a-z][a-z-]*)\(", line)
            if op and op.group(1) not in ("parameter", "tuple", "get-tuple-element", "constant", "bitcast"):
                kinds[op.group(1)] += 1
    return kinds
