"""The sine and cosine of one argument in one call: a rewrite of CasADi's generated C.

A model with an angle ``q`` has ``sin(q)`` and ``cos(q)`` in its dynamics or cost, and the
derivative of either is the other, so CasADi's C of the gradients and Hessians calls both
libm functions on the same variable (its common subexpression elimination shares each
angle, but C has no call that returns both). Each libm call reduces its argument by pi/2
again; on a Cortex-M with newlib the two calls cost about 140 instructions.

:func:`pair_sincos` finds, inside each generated function, a ``v=sin(a);`` and a
``w=cos(a);`` (either order) of the same local variable ``a`` that is not assigned between
them, and rewrites the first into one call of the runtime's ``<name>_sincos``
(runtime_c/dopus_trig.h: one reduction, both kernels) that keeps the second result in a new
local for the second line. Only plain assignments of CasADi's SX code are followed (one
local or one output entry assigned, no ``&``): any other statement between the two (a
function called on its own, a branch, a loop, a brace, an array store) ends the search, and a
variable whose address is taken anywhere in the function is never paired, so every
rewritten pair computes the same argument. Double precision only (the float build keeps ``sinf`` and
``cosf``). docs/design.md, "The generated stage functions", states the accuracy.
"""
from __future__ import annotations

import re
from typing import Dict, List, Tuple

__all__ = ["pair_sincos", "PAIR_LOCAL"]

#: The new locals holding a pair (``sc_0``, ``sc_1``, ...): CasADi's locals have no underscore.
PAIR_LOCAL = "sc_"

_FUNCTION_START = re.compile(r"^(?:static |CASADI_SYMBOL_EXPORT )?[A-Za-z_][\w \*]*?\b\w+\([^()]*\) \{$")
_TRIG = re.compile(r"^  (\w+)=(sin|cos)\((\w+)\);$")
# a statement that assigns one local or one output entry and calls nothing that could
# write a local (the address check below covers the rest)
_ASSIGN = re.compile(r"^  (?:if \(res\[\d+\]!=0\) )?(\w+|res\[\d+\]\[\d+\])=([^;{}]*);$")
_DECL = re.compile(r"^  casadi_real [\w, ]+;$")


def _pairs(body: List[str]) -> List[Tuple[int, int]]:
    """(first line, second line) of every sin/cos pair of one function body."""
    text = "\n".join(body)
    addressed = set(re.findall(r"&\s*(\w+)", text))
    open_calls: Dict[str, Tuple[int, str]] = {}   # argument -> (line, 'sin' | 'cos') not yet paired
    pairs: List[Tuple[int, int]] = []
    for k, line in enumerate(body):
        if _DECL.match(line):
            continue
        trig = _TRIG.match(line)
        if trig:
            target, fun, arg = trig.groups()
            first = open_calls.get(arg)
            if first is not None and first[1] != fun and arg not in addressed:
                pairs.append((first[0], k))
                del open_calls[arg]
            elif arg not in addressed:
                open_calls[arg] = (k, fun)
            open_calls.pop(target, None)
            continue
        assign = _ASSIGN.match(line)
        if assign is None or "&" in line:
            open_calls.clear()
            continue
        open_calls.pop(assign.group(1), None)
    return pairs


def pair_sincos(source: str, name: str) -> Tuple[str, int]:
    """CasADi's generated C with each sin/cos pair of one variable computed by one call of
    ``<name>_sincos``, and the number of pairs rewritten. The header ``<name>_trig.h`` is
    included when there is at least one."""
    lines = source.split("\n")
    out = list(lines)
    count = 0
    i = 0
    while i < len(lines):
        if not _FUNCTION_START.match(lines[i]):
            i += 1
            continue
        j = i + 1
        while j < len(lines) and lines[j] != "}":
            j += 1
        body = lines[i + 1:j]
        for first, second in sorted(_pairs(body)):
            target1, fun1, arg = _TRIG.match(body[first]).groups()
            target2, fun2, _ = _TRIG.match(body[second]).groups()
            local = f"{PAIR_LOCAL}{count}"
            field1, field2 = ("s", "c") if fun1 == "sin" else ("c", "s")
            out[i + 1 + first] = f"  {name}_sincos_pair {local}={name}_sincos({arg}); {target1}={local}.{field1};"
            out[i + 1 + second] = f"  {target2}={local}.{field2};"
            count += 1
        i = j
    if not count:
        return source, 0
    text = "\n".join(out)
    include = "#include <math.h>\n"
    if include not in text:
        raise ValueError("CasADi's C has no '#include <math.h>' line to add the sincos header after")
    return text.replace(include, include + f'#include "{name}_trig.h"\n', 1), count
