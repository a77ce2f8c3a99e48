"""Write the seed corpus of the fuzz harness (tests/fuzz/corpus/): meaningful call sequences
in the input format of fuzz_solver.c (tests/fuzz/README.md). Deterministic; the encoding
does not depend on the problem's sizes, so one corpus serves every generated solver.

    python tests/fuzz/make_corpus.py          # rewrites tests/fuzz/corpus/seed_*.bin
"""
from __future__ import annotations

import struct
from pathlib import Path

OUT = Path(__file__).resolve().parent / "corpus"

# opcodes (fuzz_solver.c, LLVMFuzzerTestOneInput)
INIT, INIT_NOMINAL, FEEDBACK, PREPARE, KKT, STEP, DEFAULTS, ZERO = 0, 1, 2, 4, 5, 6, 7, 8
SET_M, SET_MODE, SET_HESSIAN, SET_REG, SET_COST, SET_LM, SET_TOL, SET_MAXIT, SET_P, SET_P_NODE = range(9, 19)

# rd_double: table indices, tags for NaN / Inf / -Inf / raw / moderate
D_TABLE = {0.0: 0, 1.0: 1, -1.0: 2, 0.5: 3, 1e-12: 4, 1e-4: 5, 1e6: 6, 1e300: 7, -1e300: 8, 1e-300: 9}
NAN, INF, MINF = [16], [17], [18]          # 16 % 8 == 0, 17 % 8 == 1, 18 % 8 == 2


def dbl(v) -> list:
    if isinstance(v, list):
        return v
    if v in D_TABLE:
        return [D_TABLE[v]]
    if float(v * 16).is_integer() and -8 < v < 8:
        return [20, int(v * 16 + 128)]            # 20 % 8 == 4: moderate
    return [19] + list(struct.pack("<d", float(v)))  # 19 % 8 == 3: raw bits


def integer(v) -> list:
    special = {0: 0, 1: 1, -1: 2, "N-1": 3, "N": 4, "N+1": 5, "INT_MAX": 6, "INT_MIN": 7}
    if v in special:
        return [special[v]]
    assert -4 <= v <= 16
    return [(v + 4) * 12 + 9]


def x0() -> list:
    return [0]


def xstep(delta: float, mask: int = 0xFF) -> list:
    """x0 + delta on the entries whose bit (i % 8) is set in mask; delta in steps of 1e-3."""
    return [1, int(round(delta * 1e3)) + 128, mask]


def xentry(i: int, v) -> list:
    return [2, i] + dbl(v)


def feedback(state, null_x=False, null_u=False) -> list:
    return [FEEDBACK, (1 if null_x else 0) | (2 if null_u else 0)] + state


def step(state) -> list:
    return [STEP, 0] + state


def kkt(state=None, null_out=False) -> list:
    flags = (1 if state is not None else 0) | (2 if null_out else 0)
    return [KKT, flags] + (state or [])


def init_nominal(state) -> list:
    return [INIT_NOMINAL] + state


def init(state, guess=False, multipliers=False, null_x=False, guess_mod=None) -> list:
    which = (1 if guess else 0) | (2 if multipliers else 0) | (4 if null_x else 0)
    out = [INIT, which] + state
    if guess:
        out += guess_mod or [0, 0]                 # x and u arrays: the OCP file's guess
    if multipliers:
        out += [0] * 6                             # six arrays: zeros
    return out


def setter(op, *args) -> list:
    return [op] + [b for a in args for b in a]


SEEDS = {
    "receding_loop": init_nominal(x0()) + sum((step(xstep(0.02, 0b1)) for _ in range(8)), []) + kkt(),
    "fixed_study": setter(SET_MODE, integer(1)) + init_nominal(x0())
    + sum((step(xstep(0.05, 0b1)) + kkt(xstep(0.05, 0b1)) for _ in range(8)), []),
    "cold_gauss_newton_projected": setter(SET_MODE, integer(1)) + setter(SET_HESSIAN, integer(1))
    + setter(SET_REG, integer(1), dbl(1e-4)) + setter(SET_M, integer("N-1")) + init(x0(), guess=True)
    + sum((step(x0()) for _ in range(5)), []) + kkt(),
    "call_order": init_nominal(x0()) + [PREPARE] + feedback(x0()) + [PREPARE, PREPARE] + feedback(x0())
    + feedback(x0()) + [PREPARE] + kkt(xentry(0, NAN)) + step(x0()),
    "parameters_overflow_then_retry": init_nominal(x0()) + feedback(xstep(0.01))
    + setter(SET_P, [0], [2] + dbl(1e300)) + [PREPARE] + feedback(x0()) + setter(SET_P, [0], [0]) + [PREPARE]
    + step(x0()) + setter(SET_P_NODE, [0], integer(3), [1, 0] + dbl(0.5)) + step(x0()),
    "bad_setters": setter(SET_M, integer(-1)) + setter(SET_M, integer("N")) + setter(SET_M, integer("INT_MAX"))
    + setter(SET_TOL, dbl(0.0)) + setter(SET_TOL, NAN) + setter(SET_MAXIT, integer(0))
    + setter(SET_MAXIT, integer("INT_MIN")) + setter(SET_LM, dbl(-1.0)) + setter(SET_LM, INF)
    + setter(SET_REG, integer(3), dbl(1e-4)) + setter(SET_REG, integer(2), dbl(0.0))
    + setter(SET_COST, integer(2)) + setter(SET_MODE, integer(2)) + setter(SET_HESSIAN, integer(-1))
    + setter(SET_P_NODE, [0], integer(-1), [0]) + setter(SET_P_NODE, [0], integer("N+1"), [0])
    + setter(SET_M, integer("N+1"))
    + setter(SET_P, [1], [0]) + init_nominal(x0()) + step(x0()),
    "zeroed_struct": [ZERO] + feedback(x0()) + [PREPARE] + kkt() + init_nominal(x0()) + step(x0()) + step(x0())
    + [ZERO] + step(x0()),
    "qp_iteration_limit": init_nominal(x0()) + setter(SET_MAXIT, integer(1)) + feedback(xstep(0.05))
    + [PREPARE] + setter(SET_MAXIT, integer(16)) + step(xstep(0.05)) + step(x0()),
    "nonfinite_measurements": init_nominal(x0()) + feedback(xentry(0, NAN)) + feedback(xentry(1, INF))
    + feedback(xentry(2, MINF)) + feedback(x0(), null_x=True) + feedback(xentry(0, 1e300)) + [PREPARE]
    + feedback(xentry(1, 1e6)) + [PREPARE] + step(x0()),
    "full_rti_push": setter(SET_M, integer("N-1")) + init_nominal(x0()) + step(x0()) + step(xstep(0.1, 0b11))
    + step(xstep(0.05, 0b10)) + step(x0()) + kkt(),
    "bad_guesses": init(x0(), guess=True, guess_mod=[1, 3, 16, 0]) + init(x0(), multipliers=True)
    + init(x0(), guess=True, guess_mod=[2, 1e300 and 7, 0]) + init(x0(), null_x=True) + step(x0())
    + init(xentry(1, NAN)) + feedback(x0()),
    "lm_and_stored_cost": init_nominal(x0()) + setter(SET_LM, dbl(1e6)) + step(xstep(0.02)) + step(xstep(0.02))
    + setter(SET_COST, integer(0)) + setter(SET_LM, dbl(0.0)) + step(x0()) + step(x0())
    + setter(SET_REG, integer(2), dbl(1e-4)) + setter(SET_HESSIAN, integer(0)) + step(x0()) + kkt(null_out=True),
    "mode_switch_mid_run": init_nominal(x0()) + step(x0()) + setter(SET_MODE, integer(1)) + step(xstep(0.03))
    + feedback(x0()) + setter(SET_MODE, integer(0)) + [PREPARE] + step(x0()) + [DEFAULTS] + step(x0())
    + init_nominal(x0()) + step(x0()),
    "tolerances": init_nominal(x0()) + setter(SET_TOL, dbl(1e-300)) + step(xstep(0.01))
    + setter(SET_TOL, dbl(1e6)) + step(xstep(0.01)) + setter(SET_TOL, dbl(1e-4)) + step(x0()),
}


def main() -> None:
    OUT.mkdir(exist_ok=True)
    for old in OUT.glob("seed_*.bin"):
        old.unlink()
    for name, data in SEEDS.items():
        assert all(0 <= b < 256 for b in data), name
        (OUT / f"seed_{name}.bin").write_bytes(bytes(data))
    print(f"{len(SEEDS)} seeds in {OUT}")


if __name__ == "__main__":
    main()
