"""The sine and cosine in one call (runtime_c/dopus_trig.h) and the generator's rewrite of
sin/cos pairs into it (dopus_codegen/codegen/trig.py).

References: sin and cos in extended precision (numpy's long double, the C library's sinl and
cosl: 64-bit significands, 11 bits beyond double) for the error in ulp; the C library's own
sin and cos for the arguments handed to it; CasADi's evaluation of the same functions for
the rewritten generated C; the same C without the rewrite for pairs that must not be formed.
"""
from __future__ import annotations

import math
import re
import subprocess

import casadi as ca
import numpy as np
import pytest

from dopus_codegen.codegen.flags import DEFAULT_OPT, PIC, STRICT_CFLAGS
from dopus_codegen.codegen.trig import pair_sincos
from dopus_codegen.paths import runtime_c_dir

#: The bound below which dopus_sincos reduces on its own (DOPUS_SINCOS_REDUCED_MAX).
REDUCED_MAX = 1647099.0
#: The error bound stated in dopus_trig.h and docs/design.md, in ulp of the exact value.
ULP_BOUND = 1.0

WRAPPER = r"""
#include <math.h>
#include "dopus_trig.h"
void trig_many(int n, const double *x, double *s, double *c, double *ls, double *lc)
{
    int i;
    for (i = 0; i < n; ++i) {
        dopus_sincos_pair p = dopus_sincos(x[i]);
        s[i] = p.s;
        c[i] = p.c;
        ls[i] = sin(x[i]);
        lc[i] = cos(x[i]);
    }
}
"""


def _shared(tmp_path, name: str, sources, include_dirs=()) -> str:
    so = tmp_path / f"lib{name}.so"
    subprocess.run(["cc", *STRICT_CFLAGS, DEFAULT_OPT, PIC, "-shared", *(f"-I{d}" for d in include_dirs),
                    *map(str, sources), "-o", str(so), "-lm"], check=True)
    return str(so)


@pytest.fixture(scope="module")
def trig(tmp_path_factory):
    import cffi

    d = tmp_path_factory.mktemp("trig")
    (d / "wrap.c").write_text(WRAPPER)
    ffi = cffi.FFI()
    ffi.cdef("void trig_many(int n, const double *x, double *s, double *c, double *ls, double *lc);")
    lib = ffi.dlopen(_shared(d, "trig", [d / "wrap.c"], [runtime_c_dir()]))

    def run(x):
        x = np.ascontiguousarray(x, dtype=float)
        out = [np.empty_like(x) for _ in range(4)]
        lib.trig_many(x.size, ffi.from_buffer("double[]", x), *(ffi.from_buffer("double[]", o) for o in out))
        return out

    return run


def _arguments() -> np.ndarray:
    rng = np.random.default_rng(2026)
    k = np.arange(1, 200_001, dtype=float)
    parts = [
        np.linspace(-10.0, 10.0, 400_001),                               # dense, every quadrant
        rng.uniform(-REDUCED_MAX, REDUCED_MAX, 200_000),                 # random over the range
        np.exp2(rng.uniform(-40.0, math.log2(REDUCED_MAX), 200_000)),    # random magnitudes
        k * (math.pi / 2), k * (math.pi / 4), np.nextafter(k * (math.pi / 2), 0.0),   # near multiples of pi/2
        np.array([1e-300, 5e-324, 2.2250738585072014e-308, 1e-310, 7.450580596923828e-09, 1e-8,
                  math.pi / 4, np.nextafter(math.pi / 4, 1.0), 3 * math.pi / 4, math.pi, 2 * math.pi,
                  REDUCED_MAX, np.nextafter(REDUCED_MAX, 0.0)]),
    ]
    x = np.concatenate(parts)
    x = x[np.abs(x) <= REDUCED_MAX]
    return np.concatenate([x, -x])


def _ulp_error(got: np.ndarray, x: np.ndarray, f) -> np.ndarray:
    """|got - f(x)| in units of the last place of f(x) rounded to double, f in long double."""
    ref = f(x.astype(np.longdouble))
    ulp = np.spacing(np.abs(ref.astype(np.float64)))
    ulp = np.where(ulp > 0, ulp, np.spacing(0.0))
    return np.abs((got.astype(np.longdouble) - ref) / ulp.astype(np.longdouble)).astype(np.float64)


def test_within_one_ulp_below_the_bound(trig):
    if np.finfo(np.longdouble).nmant < 63:
        pytest.skip("no extended-precision long double on this platform for the reference")
    x = _arguments()
    s, c, _, _ = trig(x)
    es, ec = _ulp_error(s, x, np.sin), _ulp_error(c, x, np.cos)
    worst_s, worst_c = int(np.argmax(es)), int(np.argmax(ec))
    assert es[worst_s] <= ULP_BOUND, f"sin({x[worst_s]!r}) is {es[worst_s]:.3f} ulp off"
    assert ec[worst_c] <= ULP_BOUND, f"cos({x[worst_c]!r}) is {ec[worst_c]:.3f} ulp off"
    # most results are the correctly rounded ones (a kernel gone wrong would not be)
    assert np.mean(es <= 0.5) > 0.95 and np.mean(ec <= 0.5) > 0.95


def test_special_arguments(trig):
    x = np.array([0.0, -0.0, 5e-324, -5e-324, 1e-310, -1e-20])
    s, c, _, _ = trig(x)
    assert np.array_equal(s, x) and np.array_equal(np.signbit(s), np.signbit(x))     # sin x = x, sign of 0 kept
    assert np.all(c == 1.0)
    s, c, _, _ = trig(np.array([np.inf, -np.inf, np.nan, -np.nan]))
    assert np.all(np.isnan(s)) and np.all(np.isnan(c))


def test_beyond_the_bound_is_libm(trig):
    rng = np.random.default_rng(3)
    x = np.concatenate([[REDUCED_MAX, 2e6, 1e22, 1.7976931348623157e308],
                        np.exp2(rng.uniform(math.log2(REDUCED_MAX), 1000.0, 10_000))])
    x = np.concatenate([x, -x])
    s, c, ls, lc = trig(x)
    assert np.array_equal(s, ls) and np.array_equal(c, lc)


# ----------------------------------------------------------------------------------------
# the rewrite of CasADi's C


def _casadi_c(fun: ca.Function, tmp_path) -> str:
    cg = ca.CodeGenerator("trig_casadi", {"casadi_int": "int", "casadi_real": "double", "with_header": False})
    cg.add(fun)
    cg.generate(str(tmp_path) + "/")
    return (tmp_path / "trig_casadi.c").read_text()


def _evaluator(source: str, tmp_path, tag: str, n_in: int, n_out: int):
    """The generated function 'f' compiled into a shared library, called from Python."""
    import cffi

    src = tmp_path / f"f_{tag}.c"
    src.write_text(source.replace('#include "trig_trig.h"', '#include "dopus_trig.h"').replace(
        "trig_sincos", "dopus_sincos"))
    so = tmp_path / f"libf_{tag}.so"
    subprocess.run(["cc", "-std=c99", DEFAULT_OPT, PIC, "-shared", f"-I{runtime_c_dir()}", str(src), "-o", str(so),
                    "-lm"], check=True)
    ffi = cffi.FFI()
    ffi.cdef("int f(const double** arg, double** res, int* iw, double* w, int mem);")
    lib = ffi.dlopen(str(so))

    def call(xs):
        bufs = [np.ascontiguousarray(np.atleast_1d(np.asarray(v, dtype=float))) for v in xs]
        outs = [np.zeros(1) for _ in range(n_out)]
        arg = ffi.new("const double*[]", [ffi.from_buffer("double[]", b) for b in bufs])
        res = ffi.new("double*[]", [ffi.from_buffer("double[]", o) for o in outs])
        w = ffi.new("double[]", 1000)
        iw = ffi.new("int[]", 10)
        assert lib.f(arg, res, iw, w, 0) == 0
        return np.array([o[0] for o in outs])

    return call


def test_rewritten_functions_match_casadi(tmp_path):
    """A model-like function with angles, their sums, products and derivatives: every sin/cos
    pair of one argument is rewritten, and the compiled C matches CasADi's evaluation."""
    q = ca.SX.sym("q", 3)
    a, b, c = q[0], q[1], q[2]
    e = ca.vertcat(ca.sin(a) * ca.cos(b) + ca.cos(a + b) * c, ca.sin(a + b) ** 2 + ca.cos(c) * ca.sin(c),
                   ca.sin(ca.cos(a)) + ca.cos(ca.sin(b)), 3.0 * ca.sin(1e4 * c) + ca.cos(1e7 * a))
    jac = ca.jacobian(e, q)
    hess = ca.hessian(ca.dot(e, ca.DM([1.0, -2.0, 0.5, 0.25])), q)[0]
    outs = [e[i] for i in range(4)] + [jac[i, j] for i in range(4) for j in range(3)] + \
        [hess[i, j] for i in range(3) for j in range(3)]
    fun = ca.Function("f", [a, b, c], outs, {"cse": True})
    plain = _casadi_c(fun, tmp_path)
    rewritten, count = pair_sincos(plain, "trig")
    calls = len(re.findall(r"=(?:sin|cos)\(", plain))
    assert count >= 6 and len(re.findall(r"=(?:sin|cos)\(", rewritten)) == calls - 2 * count
    f_new = _evaluator(rewritten, tmp_path, "new", 3, len(outs))
    f_old = _evaluator(plain, tmp_path, "old", 3, len(outs))
    rng = np.random.default_rng(5)
    for point in [rng.uniform(-4.0, 4.0, 3) for _ in range(50)] + [np.array([0.0, -0.0, 1e-9]),
                                                                   np.array([1e3, -2e5, 7.0])]:
        ref = np.array([float(v) for v in fun(*point)])
        scale = np.maximum(1.0, np.abs(ref))
        assert np.max(np.abs(f_new(point) - ref) / scale) <= 1e-12
        assert np.max(np.abs(f_new(point) - f_old(point)) / scale) <= 1e-12


HAND_WRITTEN = """#include <math.h>
static int casadi_f0(const double** arg, double** res, int* iw, double* w, int mem) {
  double a0, a1, a2, a3, a4;
  a0=arg[0]? arg[0][0] : 0;
  a1=sin(a0);
  a2=cos(a0);
  a3=sin(a2);
  a4=(a3+a1);
  a1=cos(a2);
  a2=(a2*a4);
  a4=sin(a2);
  a3=cos(a4);
  a0=cos(a0);
  a0=(a0+a1);
  a0=(a0+a3);
  a0=(a0+a2);
  if (res[0]!=0) res[0][0]=a0;
  a1=(a0*a0);
  a2=sin(a1);
  w[0]=a1;
  a3=cos(a1);
  a3=(a3+a2);
  if (res[0]!=0) res[0][1]=a3;
  return 0;
}
int f(const double** arg, double** res, int* iw, double* w, int mem) {
  return casadi_f0(arg, res, iw, w, mem);
}
"""


def test_rewrite_pairs_only_the_same_value(tmp_path):
    """Pairs whose argument is assigned between the two calls, or separated by a statement
    the rewrite does not follow, stay libm calls; the others are rewritten."""
    rewritten, count = pair_sincos(HAND_WRITTEN, "trig")
    # a0: sin and cos paired; a2: sin, then cos of the same a2 (paired), then a2 reassigned, so
    # sin(a2) after it pairs with nothing; a4 only cos; a0=cos(a0) comes after the pair; a1: the
    # statement w[0]=a1 between the two calls ends the search
    assert count == 2, rewritten
    assert "a2=trig_sincos" not in rewritten and "a2=sin(a1);" in rewritten and "a3=cos(a1);" in rewritten
    f_new = _evaluator(rewritten, tmp_path, "hw_new", 1, 2)
    f_old = _evaluator(HAND_WRITTEN, tmp_path, "hw_old", 1, 2)
    for x in np.linspace(-5.0, 5.0, 101):
        np.testing.assert_allclose(f_new([x]), f_old([x]), rtol=1e-14, atol=1e-14)
