"""The code generator pipeline: generate, build, make, the standalone main, two problems in
one program, the allocator-free static library and the CLI errors.

Numbers are checked against independent sources: the generated C wrappers against CasADi's
own evaluation of the same functions, the generated data against the Discretized problem
and the IPOPT solution, the standalone main against the Python reference DOPUS and IPOPT.
"""
from __future__ import annotations

import difflib
import json
import re
import shutil
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from click.testing import CliRunner

from dopus_codegen.codegen.flags import DEFAULT_OPT, PIC, STRICT_CFLAGS

from dopus_codegen.codegen.build import BuildError, build
from dopus_codegen.cli import main as cli_main
from dopus_codegen.codegen.generate import CodegenError, generate, rename_placeholder

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
EXAMPLES = {"robot_arm": ROOT / "examples" / "robot_arm.py", "unicycle": ROOT / "examples" / "unicycle.py"}
DISC_FIXTURE = {"robot_arm": "robot_disc", "unicycle": "second_disc"}
SOLUTION_FIXTURE = {"robot_arm": "robot_solution", "unicycle": "second_solution"}
NAMES = sorted(EXAMPLES)
ALLOCATORS = {"malloc", "calloc", "realloc", "free"}
MAIN_ITERATIONS = 10  # ITERATIONS of templates/main.c.j2
# C against the Python reference: the C QP is an interior-point method whose solution sits
# about 1e-8 inside an active bound where the reference's active-set polish puts it exactly
# on the bound, so controls agree to that level and KKT values to the same floor.
U_RTOL, U_ATOL = 1e-6, 1e-7
KKT_RTOL, KKT_ATOL = 1e-6, 1e-8


def _wants_nominal(disc) -> bool:
    return bool(disc.options.get("offline_guess", False))


# ----------------------------------------------------------------------------------------
# fixtures: each example generated and built once per module


@pytest.fixture(scope="module")
def generated(request, tmp_path_factory):
    """{name: (disc, folder)} generated into a temporary folder with the OCP's options."""
    out = {}
    base = tmp_path_factory.mktemp("gen")
    for name in NAMES:
        disc = request.getfixturevalue(DISC_FIXTURE[name])
        out[name] = (disc, generate(disc, base / name))
    return out


@pytest.fixture(scope="module")
def built(generated):
    return {name: build(folder) for name, (disc, folder) in generated.items()}


def _meta(folder: Path) -> dict:
    return json.loads(next(folder.glob("*_meta.json")).read_text())


def _defines(text: str) -> dict:
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"#define (\w+) (-?\d+)\s*$", text, re.M)}


def _glue_cdef(folder: Path, name: str) -> str:
    """cffi declarations of <name>_funcs.h and <name>_problem.h with the macros expanded
    from the generated sizes header (so the test reads the same declarations the C does)."""
    NAME = name.upper()
    consts = _defines((folder / f"{name}_sizes.h").read_text())
    text = (folder / f"{name}_funcs.h").read_text() + (folder / f"{name}_problem.h").read_text()
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    text = "\n".join(ln for ln in text.splitlines() if not ln.strip().startswith("#"))
    text = text.replace(f"{NAME}_INTERNAL ", "")
    text = text.replace("extern const ", "extern ")  # cffi reads `const` scalars as constants
    for key in sorted(consts, key=len, reverse=True):
        text = text.replace(key, str(consts[key]))
    text = re.sub(NAME + r"_DIM\((\d+)\)", lambda m: str(max(int(m.group(1)), 1)), text)
    text = re.sub(r"\[([\d +]+)\]", lambda m: f"[{sum(int(t) for t in m.group(1).split('+'))}]", text)
    real = "float" if consts.get(f"{NAME}_REAL_FLOAT") == 1 else "double"
    return f"typedef {real} {name}_real;\n" + text


def _funcs_library(folder: Path, name: str, out_dir: Path) -> Path:
    """The module of the function wrappers (<name>_funcs.c, static in the solver library)
    compiled alone with CasADi's file into a shared library, for the tests of the wrappers."""
    lib = out_dir / f"lib{name}_funcs.so"
    subprocess.run(["cc", DEFAULT_OPT, PIC, "-shared", *STRICT_CFLAGS, f"-I{folder}", str(folder / f"{name}_funcs.c"),
                    str(folder / f"{name}_casadi.c"), "-o", str(lib), "-lm"], check=True)
    return lib


def _load_glue(folder: Path, name: str, shared_lib: Path):
    import cffi

    ffi = cffi.FFI()
    ffi.cdef(_glue_cdef(folder, name))
    return ffi, ffi.dlopen(str(shared_lib))


# ----------------------------------------------------------------------------------------
# 1. the checked-in generated/ folders are what the generator produces, byte for byte


def _first_diff(a: str, b: str, label: str) -> str:
    diff = difflib.unified_diff(a.splitlines(), b.splitlines(), f"generated/{label}", f"regenerated/{label}",
                                lineterm="", n=1)
    return "\n".join(list(diff)[:30])


@pytest.mark.parametrize("name", NAMES)
def test_checked_in_folder_is_regenerated_byte_for_byte(name, generated, tmp_path):
    checked = GENERATED / name
    assert (checked / f"{name}_meta.json").is_file(), \
        f"generated/{name} is missing: run `make generate` and commit the folder"
    meta = _meta(checked)
    assert meta["casadi_version"] == ca.__version__, (
        f"generated/{name} was produced with CasADi {meta['casadi_version']} but CasADi {ca.__version__} "
        "is installed; the generated C depends on the exact CasADi version. Install the pinned "
        "version (pyproject.toml: casadi==3.8.2), or, if the pin was changed on purpose, regenerate "
        "with `make generate` and commit generated/.")
    disc, fresh = generated[name]
    again = generate(disc, tmp_path / name)  # a second generation in the same process
    new_files = sorted(p.name for p in fresh.iterdir() if p.is_file())
    old_files = sorted(p.name for p in checked.iterdir() if p.is_file())
    assert new_files == old_files, (f"generated/{name} holds {sorted(set(old_files) - set(new_files))} extra and "
                                    f"lacks {sorted(set(new_files) - set(old_files))}: run `make generate`")
    for fname in new_files:
        a, b, c = ((d / fname).read_bytes() for d in (checked, fresh, again))
        assert b == c, f"generating twice gave different bytes in {fname}"
        source = ROOT / "runtime_c" / ("dopus_" + fname[len(name) + 1:])
        origin = f" (copied from runtime_c/{source.name})" if fname.startswith(name + "_") and source.is_file() else ""
        assert a == b, (f"generated/{name}/{fname}{origin} differs from a fresh generation; run `make generate` "
                        f"and commit generated/ if the change is intended:\n"
                        + _first_diff(a.decode(), b.decode(), f"{name}/{fname}"))


# ----------------------------------------------------------------------------------------
# 2. the generated C wrappers compute what CasADi computes


def _colmajor(buf, rows, cols):
    return np.frombuffer(buf, dtype=float, count=rows * cols).reshape(cols, rows).T if rows * cols else \
        np.zeros((rows, cols))


@pytest.mark.parametrize("name", NAMES)
def test_generated_functions_match_casadi(name, generated, tmp_path):
    disc, folder = generated[name]
    ffi, lib = _load_glue(folder, name, _funcs_library(folder, name, tmp_path))
    N, nx, nu, nw, npar, ng, nr, ne = (disc.N, disc.nx, disc.nu, disc.nw, disc.np, disc.ng, disc.nr, disc.ne)
    rng = np.random.default_rng(7)
    wk = ffi.new(f"{name}_fun_work *")

    def arr(v):
        v = np.ascontiguousarray(np.asarray(v, dtype=float).reshape(-1))
        return v if v.size else np.zeros(1)

    def ptr(v):
        return ffi.cast("double *", ffi.from_buffer(v))

    def out(n):
        return np.zeros(max(n, 1))

    def close(c, ref, what):
        ref = np.asarray(ref, dtype=float)
        c = np.asarray(c, dtype=float).reshape(ref.shape)
        scale = max(1.0, float(np.max(np.abs(ref))) if ref.size else 1.0)
        err = float(np.max(np.abs(c - ref))) if ref.size else 0.0
        assert err <= 1e-12 * scale, f"{name} {what}: C differs from CasADi by {err:.3e} (scale {scale:.3e})"

    for trial in range(3):
        k = int(rng.integers(N))
        x = arr(disc.initial_guess.x[k] + 0.1 * rng.standard_normal(nx))
        u = arr(disc.initial_guess.u[k] + 0.1 * rng.standard_normal(nu))
        p = arr(disc.p0[k] + 0.1 * rng.standard_normal(npar)) if npar else np.zeros(1)
        lam, mu_g = arr(rng.standard_normal(nx)), arr(rng.standard_normal(ng)) if ng else np.zeros(1)
        mu_r, nuv = (arr(rng.standard_normal(nr)) if nr else np.zeros(1)), (arr(rng.standard_normal(ne)) if ne else np.zeros(1))
        xs, us, ps = x[:nx], u[:nu], p[:npar]
        ls, mgs, mrs, nus = lam[:nx], mu_g[:ng], mu_r[:nr], nuv[:ne]

        phi, l, g = out(nx), out(1), out(ng)
        assert getattr(lib, f"{name}_eval_stage_eval")(ptr(x), ptr(u), ptr(p), ptr(phi), ptr(l), ptr(g), wk) == 0
        ref = disc.stage_eval(xs, us, ps)
        close(phi[:nx], ref[0], "stage_eval phi"); close(l[:1], ref[1], "stage_eval l"); close(g[:ng], ref[2], "stage_eval g")

        gL, phi, l, g = out(nw), out(nx), out(1), out(ng)
        assert getattr(lib, f"{name}_eval_stage_grad")(ptr(x), ptr(u), ptr(p), ptr(lam), ptr(mu_g), ptr(gL),
                                                          ptr(phi), ptr(l), ptr(g), wk) == 0
        ref = disc.stage_grad(xs, us, ps, ls, mgs)
        for i, (c, what) in enumerate([(gL[:nw], "gL"), (phi[:nx], "phi"), (l[:1], "l"), (g[:ng], "g")]):
            close(c, ref[i], f"stage_grad {what}")

        for gn, fun in ((0, disc.stage_hess_exact), (1, disc.stage_hess_gn)):
            A, Phi, C = out(nw * nw), out(nx * nw), out(ng * nw)
            rc = getattr(lib, f"{name}_eval_stage_hess")(gn, ptr(x), ptr(u), ptr(p), ptr(lam), ptr(mu_g),
                                                            ptr(A), ptr(Phi), ptr(C), wk)
            if fun is None:
                assert rc != 0, "stage_hess with gauss_newton=1 must fail without a least-squares cost"
                continue
            assert rc == 0
            ref = fun(xs, us, ps, ls, mgs)
            close(_colmajor(A, nw, nw), ref[0], f"stage_hess[{gn}] A")
            close(_colmajor(Phi, nx, nw), ref[1], f"stage_hess[{gn}] Phi")
            close(_colmajor(C, ng, nw), ref[2], f"stage_hess[{gn}] C")

        E, r, req = out(1), out(nr), out(ne)
        assert getattr(lib, f"{name}_eval_term_eval")(ptr(x), ptr(p), ptr(E), ptr(r), ptr(req), wk) == 0
        ref = disc.term_eval(xs, ps)
        close(E[:1], ref[0], "term_eval E"); close(r[:nr], ref[1], "term_eval r"); close(req[:ne], ref[2], "term_eval r_eq")

        gL, E, r, req = out(nx), out(1), out(nr), out(ne)
        assert getattr(lib, f"{name}_eval_term_grad")(ptr(x), ptr(p), ptr(mu_r), ptr(nuv), ptr(gL), ptr(E),
                                                         ptr(r), ptr(req), wk) == 0
        ref = disc.term_grad(xs, ps, mrs, nus)
        for i, (c, what) in enumerate([(gL[:nx], "gL"), (E[:1], "E"), (r[:nr], "r"), (req[:ne], "r_eq")]):
            close(c, ref[i], f"term_grad {what}")

        for gn, fun in ((0, disc.term_hess_exact), (1, disc.term_hess_gn)):
            A, R, Req = out(nx * nx), out(nr * nx), out(ne * nx)
            assert getattr(lib, f"{name}_eval_term_hess")(gn, ptr(x), ptr(p), ptr(mu_r), ptr(nuv), ptr(A),
                                                             ptr(R), ptr(Req), wk) == 0
            ref = fun(xs, ps, mrs, nus)
            close(_colmajor(A, nx, nx), ref[0], f"term_hess[{gn}] A")
            close(_colmajor(R, nr, nx), ref[1], f"term_hess[{gn}] R")
            close(_colmajor(Req, ne, nx), ref[2], f"term_hess[{gn}] R_eq")

        xdot = out(nx)
        assert getattr(lib, f"{name}_eval_ode")(ptr(x), ptr(u), ptr(p), ptr(xdot), wk) == 0
        close(xdot[:nx], disc.ode(xs, us, ps), "ode")


@pytest.mark.parametrize("name", NAMES)
def test_generated_data_is_the_problem(name, generated, built, request):
    """Every number of <name>_problem.c reads back exactly (round-trip printing, INFINITY)."""
    disc, folder = generated[name]
    ffi, lib = _load_glue(folder, name, built[name].shared_lib)
    N, nx, nu = disc.N, disc.nx, disc.nu

    def read(sym, n):
        return np.frombuffer(ffi.buffer(getattr(lib, f"{name}_{sym}")), dtype=float, count=n).copy()

    for sym, ref in [("lbx", disc.lbx), ("ubx", disc.ubx), ("lbu", disc.lbu), ("ubu", disc.ubu),
                     ("lg", disc.lg), ("ug", disc.ug), ("lr", disc.lr), ("ur", disc.ur), ("x0_default", disc.x0),
                     ("p_default", disc.p0[0])]:
        ref = np.asarray(ref, dtype=float).reshape(-1)
        np.testing.assert_array_equal(read(sym, ref.size), ref, err_msg=f"{name}_{sym}")
    np.testing.assert_array_equal(read("guess_x", (N + 1) * nx), np.asarray(disc.initial_guess.x).reshape(-1))
    np.testing.assert_array_equal(read("guess_u", N * nu), np.asarray(disc.initial_guess.u).reshape(-1))
    assert getattr(lib, f"{name}_dt") == disc.dt
    # the generated settings are the OCP file's options
    import cffi

    sffi = cffi.FFI()
    sffi.cdef((folder / f"{name}_cdef.h").read_text())
    slib = sffi.dlopen(str(built[name].shared_lib))
    st = sffi.new(f"{name}_settings *")
    getattr(slib, f"{name}_settings_default")(st)
    assert st.M == disc.options["M"]
    assert st.hessian == {"exact": 0, "gauss-newton": 1}[disc.options["hessian"]]
    assert st.regularization == {"none": 0, "project": 1, "mirror": 2}[disc.options["regularization"]]
    assert st.reg_eps == disc.options.get("reg_eps", 1e-4)
    lm = disc.options.get("lm", "auto")
    assert (st.lm_auto, st.lm) == ((1, 0.0) if lm == "auto" else (0, float(lm)))

    meta = _meta(folder)
    assert meta["has_nominal"] == _wants_nominal(disc)
    if meta["has_nominal"]:
        sol, info = request.getfixturevalue(SOLUTION_FIXTURE[name])
        assert info["success"]
        for sym, ref in [("x", sol.x), ("u", sol.u), ("lam", sol.lam), ("mu_b", sol.mu_b), ("mu_bN", sol.mu_bN)]:
            ref = np.asarray(ref, dtype=float).reshape(-1)
            np.testing.assert_array_equal(read(f"nominal_{sym}", ref.size), ref, err_msg=f"nominal_{sym}")
        for sym, ref in [("mu_g", sol.mu_g), ("mu_r", sol.mu_r), ("nu", sol.nu)]:
            ref = np.asarray(ref, dtype=float).reshape(-1)
            if ref.size:
                np.testing.assert_array_equal(read(f"nominal_{sym}", ref.size), ref, err_msg=f"nominal_{sym}")


def test_robot_arm_carries_the_offline_guess(robot_disc):
    """docs/design.md section 8: from the cold guess the exact-Hessian DOPUS diverges, so the
    robot-arm controller must start warm from the offline solution carried as data."""
    assert _wants_nominal(robot_disc), \
        "examples/robot_arm.py must set options(offline_guess=True) so generated/robot_arm starts warm"


# ----------------------------------------------------------------------------------------
# 3. make in the folder, the standalone main against the Python reference and IPOPT


def _make(folder: Path) -> None:
    proc = subprocess.run(["make", "-j2"], cwd=folder, capture_output=True, text=True)
    assert proc.returncode == 0, f"make failed in {folder}:\n{proc.stdout}\n{proc.stderr}"


def _parse_run(stdout: str, nu: int) -> dict:
    """{phase: [(status, u0, kkt) per iteration]} of a main_<name> output."""
    runs: dict = {}
    for line in stdout.splitlines():
        tok = line.split()
        if len(tok) >= 2 and tok[0] in ("fixed", "receding"):
            assert tok[2] == "status" and tok[4] == "u0" and tok[5 + nu] == "kkt", line
            runs.setdefault(tok[0], []).append(
                (int(tok[3]), np.array([float(t) for t in tok[5:5 + nu]]), float(tok[6 + nu])))
    return runs


def _reference_run(disc, nominal, mode: str, iterations: int):
    from dopus_codegen.reference.dopus import ReferenceDopus

    o = disc.options
    ref = ReferenceDopus(disc, M=o["M"], mode=mode, hessian=o["hessian"], regularization=o["regularization"],
                         reg_eps=o.get("reg_eps", 1e-4), lm=o.get("lm", 0.0))
    xhat = np.asarray(disc.x0, dtype=float).copy()
    ref.init(xhat, nominal)
    rows = [(np.zeros(disc.nu), ref.kkt(xhat)["kkt"])]
    for _ in range(iterations):
        u0 = np.asarray(ref.feedback(xhat), dtype=float).copy()
        if mode == "receding":
            xhat = np.asarray(disc.stage_eval(xhat, u0, disc.p0[0])[0], dtype=float).reshape(-1)
        ref.prepare()
        rows.append((u0, ref.kkt(xhat)["kkt"]))
    return rows


@pytest.mark.parametrize("name", NAMES)
def test_make_builds_and_main_matches_reference(name, generated, request):
    disc, folder = generated[name]
    _make(folder)
    for lib in (folder / "build" / f"lib{name}.a", folder / "build" / f"lib{name}.so"):
        assert lib.is_file()
    proc = subprocess.run([str(folder / "build" / f"main_{name}")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"main_{name} failed:\n{proc.stdout}\n{proc.stderr}"
    runs = _parse_run(proc.stdout, disc.nu)
    # the cffi declarations cut from the public header load the library dopus_codegen.codegen.build made,
    # and it has the same struct layout as the program make built
    import cffi

    res = build(folder)
    ffi = cffi.FFI()
    ffi.cdef(res.cdef_path.read_text())
    lib = ffi.dlopen(str(res.shared_lib))
    head = proc.stdout.splitlines()[0].split()
    assert head[:2] == ["problem", name] and int(head[head.index("sizeof") + 1]) == getattr(lib, f"{name}_solver_sizeof")()
    assert ffi.string(getattr(lib, f"{name}_name")()).decode() == name
    nominal = None
    if _wants_nominal(disc):
        nominal, info = request.getfixturevalue(SOLUTION_FIXTURE[name])
    for mode in ("fixed", "receding"):
        c_rows = runs[mode]
        assert len(c_rows) == MAIN_ITERATIONS + 1 and all(st == 0 for st, _, _ in c_rows)
        ref_rows = _reference_run(disc, nominal, mode, MAIN_ITERATIONS)
        for k, ((_, u_c, kkt_c), (u_r, kkt_r)) in enumerate(zip(c_rows, ref_rows)):
            np.testing.assert_allclose(u_c, u_r, rtol=U_RTOL, atol=U_ATOL,
                                       err_msg=f"{name} {mode} iteration {k}: u0 of main vs reference")
            assert abs(kkt_c - kkt_r) <= KKT_RTOL * kkt_r + KKT_ATOL, \
                f"{name} {mode} iteration {k}: KKT {kkt_c:.6e} (main) vs {kkt_r:.6e} (reference)"
    if nominal is not None:
        # fixed x0 from the NLP solution: the iteration stays at the IPOPT solution
        for k, (_, u_c, kkt_c) in enumerate(runs["fixed"][1:], start=1):
            np.testing.assert_allclose(u_c, nominal.u[0], rtol=0, atol=1e-7,
                                       err_msg=f"{name} fixed iteration {k}: u0 vs IPOPT")
            assert kkt_c < 1e-7


@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is not installed (the CMake fragment is optional)")
def test_cmake_fragment_builds_main(generated, tmp_path):
    """include(<name>.cmake) gives a static library target the standalone main links to;
    the program prints the same numbers as the one built by the folder's Makefile."""
    name = "unicycle"
    disc, folder = generated[name]
    (tmp_path / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.13)\nproject(fragment C)\n"
        f'include("{folder}/{name}.cmake")\n'
        f'add_executable(main_{name} "{folder}/{name}_main.c")\n'
        f"target_link_libraries(main_{name} PRIVATE {name})\n")
    for cmd in (["cmake", "-S", ".", "-B", "b", "-DCMAKE_BUILD_TYPE=Release"], ["cmake", "--build", "b", "-j2"]):
        proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True)
        assert proc.returncode == 0, f"{' '.join(cmd)} failed:\n{proc.stdout}\n{proc.stderr}"
    _make(folder)
    outs = [subprocess.run([str(exe)], capture_output=True, text=True, timeout=120)
            for exe in (tmp_path / "b" / f"main_{name}", folder / "build" / f"main_{name}")]
    cm, mk = (_parse_run(o.stdout, disc.nu) for o in outs)
    assert outs[0].returncode == outs[1].returncode
    for mode in mk:
        for (s1, u1, k1), (s2, u2, k2) in zip(cm[mode], mk[mode]):
            assert s1 == s2
            np.testing.assert_allclose(u1, u2, rtol=1e-9, atol=1e-12)
            assert abs(k1 - k2) <= 1e-9 * max(k2, 1e-12) + 1e-14


# ----------------------------------------------------------------------------------------
# 4. no allocator in any object of the static libraries


def _symbols(lib: Path) -> set:
    """{(object, symbol)} of every defined or undefined symbol in a static library."""
    proc = subprocess.run(["nm", "-A", str(lib)], capture_output=True, text=True, check=True)
    syms = set()
    for line in proc.stdout.splitlines():
        m = re.match(r"^.*:([^:]+\.o):\s*(?:[0-9a-fA-F]+\s+)?[A-Za-z?]\s+(\S+)$", line)
        if m:
            syms.add((m.group(1), m.group(2)))
    return syms


@pytest.mark.parametrize("name", NAMES)
def test_static_library_has_no_allocator(name, built):
    lib = built[name].static_lib
    syms = _symbols(lib)
    objects = {obj for obj, _ in syms}
    assert any(f"{name}_solver" in o for o in objects) and any(f"{name}_casadi" in o for o in objects), objects
    found = sorted((obj, sym) for obj, sym in syms if sym in ALLOCATORS or sym.lstrip("_") in ALLOCATORS)
    assert not found, f"allocator symbols in lib{name}.a: {found}"
    # the check sees symbols at all: the CasADi object needs sin/cos from libm
    assert any(sym in ("sin", "cos", "sincos") for _, sym in syms)


@pytest.mark.parametrize("name", NAMES)
def test_static_library_exports_only_the_api(name, generated, built):
    """Defined global symbols of lib<name>.a: the functions of the public header (its cffi
    part), the problem data of <name>_problem.h and CasADi's functions; no runtime internal
    (the modules are static in the one translation unit of <name>_solver.c)."""
    folder = generated[name][1]
    proc = subprocess.run(["nm", "-g", "--defined-only", str(built[name].static_lib)], capture_output=True, text=True,
                          check=True)
    exported = {ln.split()[-1].lstrip("_") for ln in proc.stdout.splitlines() if re.match(r"^[0-9a-fA-F]+\s+[A-Z]\s", ln)}
    cdef = (folder / f"{name}_cdef.h").read_text()
    api = set(re.findall(rf"\b({name}_\w+)\s*\(", cdef))
    data = {sym for ln in (folder / f"{name}_problem.h").read_text().splitlines() if ln.startswith("extern const")
            for sym in re.findall(rf"\b({name}_\w+)\s*(?:\[|;)", ln)}
    casadi = set(re.findall(rf"\b({name}_\w+)\s*\(", (folder / f"{name}_casadi.h").read_text()))
    casadi |= {sym for sym in exported if sym.startswith(f"{name}_casadi_")}   # CasADi's helpers
    leaked = sorted(exported - api - data - casadi)
    assert not leaked, f"lib{name}.a exports runtime internals: {leaked}"
    assert api <= exported and len(api) <= 40, (len(api), sorted(api - exported))


# ----------------------------------------------------------------------------------------
# 5. two generated problems in one program, side by side


TWO_PROBLEMS_C = r"""
#include <stdio.h>
#include "robot_arm_casadi.h"
#include "robot_arm_problem.h"
#include "robot_arm_solver.h"
#include "unicycle_casadi.h"
#include "unicycle_problem.h"
#include "unicycle_solver.h"

static robot_arm_solver a;
static unicycle_solver b;

static void show(const char *name, int k, int status, const double *u0, int nu, const double *kkt4)
{
    int i;
    double kkt = kkt4[0];
    for (i = 1; i < 4; ++i) kkt = kkt4[i] > kkt ? kkt4[i] : kkt;
    printf("%s %d status %d u0", name, k, status);
    for (i = 0; i < nu; ++i) printf(" %.17g", u0[i]);
    printf(" kkt %.17g\n", kkt);
}

int main(void)
{
    double ua[ROBOT_ARM_NU] = {0}, ub[UNICYCLE_NU] = {0}, ka[4], kb[4];
    robot_arm_settings sta;
    unicycle_settings stb;
    int k, sa, sb;
    robot_arm_settings_default(&sta);
    unicycle_settings_default(&stb);
    sta.mode = ROBOT_ARM_MODE_FIXED;
    stb.mode = UNICYCLE_MODE_FIXED;
    if (robot_arm_setup(&a, &sta) || unicycle_setup(&b, &stb)) return 1;
#if ROBOT_ARM_HAS_NOMINAL
    sa = robot_arm_init_nominal(&a, robot_arm_x0_default);
#else
    sa = robot_arm_init(&a, robot_arm_x0_default, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
#endif
#if UNICYCLE_HAS_NOMINAL
    sb = unicycle_init_nominal(&b, unicycle_x0_default);
#else
    sb = unicycle_init(&b, unicycle_x0_default, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
#endif
    if (sa || sb) return 1;
    robot_arm_kkt_eval(&a, robot_arm_x0_default, ka);
    unicycle_kkt_eval(&b, unicycle_x0_default, kb);
    show("robot_arm", 0, sa, ua, ROBOT_ARM_NU, ka);
    show("unicycle", 0, sb, ub, UNICYCLE_NU, kb);
    for (k = 1; k <= 10; ++k) {
        /* interleaved: any shared state between the two solvers would show here */
        sa = robot_arm_feedback(&a, robot_arm_x0_default, ua);
        sb = unicycle_feedback(&b, unicycle_x0_default, ub);
        if (!sa) sa = robot_arm_prepare(&a);
        if (!sb) sb = unicycle_prepare(&b);
        if (!sa) sa = robot_arm_kkt_eval(&a, robot_arm_x0_default, ka);
        if (!sb) sb = unicycle_kkt_eval(&b, unicycle_x0_default, kb);
        show("robot_arm", k, sa, ua, ROBOT_ARM_NU, ka);
        show("unicycle", k, sb, ub, UNICYCLE_NU, kb);
        if (sa || sb) return 1;
    }
    printf("sizes %lu %lu\n", (unsigned long)sizeof a, (unsigned long)sizeof b);
    return 0;
}
"""


def test_two_problems_link_into_one_program(generated, built, tmp_path):
    assert set(NAMES) == {"robot_arm", "unicycle"}
    src = tmp_path / "two.c"
    src.write_text(TWO_PROBLEMS_C)
    exe = tmp_path / "two"
    cmd = ["cc", DEFAULT_OPT, *STRICT_CFLAGS, str(src)]
    for name in NAMES:
        cmd += ["-I", str(generated[name][1])]
    cmd += [str(built[name].static_lib) for name in NAMES] + ["-lm", "-o", str(exe)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, f"compiling two problems into one program failed:\n{proc.stderr}"
    proc = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"two-problem program failed:\n{proc.stdout}\n{proc.stderr}"
    # each solver, run alone by the Python reference, gives the same iterates
    for name in NAMES:
        disc = generated[name][0]
        rows = [ln.split() for ln in proc.stdout.splitlines() if ln.startswith(name + " ")]
        rows = [(int(t[3]), np.array([float(v) for v in t[5:5 + disc.nu]]), float(t[6 + disc.nu])) for t in rows]
        assert len(rows) == 11 and all(st == 0 for st, _, _ in rows)
        nominal = None
        if _wants_nominal(disc):
            from dopus_codegen.reference.offline import solve_ocp
            nominal = solve_ocp(disc, disc.x0)[0]
        ref_rows = _reference_run(disc, nominal, "fixed", 10)
        for k, ((_, u_c, kkt_c), (u_r, kkt_r)) in enumerate(zip(rows, ref_rows)):
            np.testing.assert_allclose(u_c, u_r, rtol=U_RTOL, atol=U_ATOL, err_msg=f"{name} iteration {k}")
            assert abs(kkt_c - kkt_r) <= KKT_RTOL * kkt_r + KKT_ATOL, f"{name} iteration {k}: KKT {kkt_c} vs {kkt_r}"


# ----------------------------------------------------------------------------------------
# 6. renaming, rebuild skipping, build errors


@pytest.mark.parametrize("name", NAMES)
def test_no_placeholder_left_in_generated_folder(name, generated):
    folder = generated[name][1]
    for path in sorted(folder.iterdir()):
        if path.is_file():
            assert "dopus" not in path.name.replace("dopus-gen", "")
            hits = re.findall(r"\b(?:dopus|DOPUS)_\w+", path.read_text())
            assert not hits, f"{path.name} still uses the placeholder prefix: {sorted(set(hits))[:5]}"


def test_rename_is_one_pass():
    assert rename_placeholder("dopus_init DOPUS_N dopus_x_dopus_y", "dopus_x") == \
        "dopus_x_init DOPUS_X_N dopus_x_x_dopus_x_y"


def test_build_skips_unchanged_and_reports_compiler_errors(generated, tmp_path, monkeypatch):
    src = generated["unicycle"][1]
    folder = tmp_path / "unicycle"
    shutil.copytree(src, folder, ignore=shutil.ignore_patterns("build"))
    monkeypatch.chdir(tmp_path)
    first = build("unicycle")  # a relative folder, as typed on the command line
    assert first.rebuilt and first.shared_lib.is_file() and first.static_lib.is_file()
    assert first.cdef_path.read_text().count("unicycle_feedback") == 1
    assert not build(folder).rebuilt
    assert build(folder, opt="-O1").rebuilt
    with (folder / "unicycle_problem.c").open("a") as fh:
        fh.write("\nthis is not C;\n")
    with pytest.raises(BuildError) as err:
        build(folder)
    msg = str(err.value)
    assert "compiling unicycle_problem.c" in msg and "unicycle_problem.c:" in msg and "error" in msg


def test_cli_build_shows_the_compiler_diagnostic(generated, tmp_path):
    """dopus-gen build on a folder whose CasADi file does not compile: exit 2 and the
    compiler's own error line in the message (not only its last line, 'all warnings being
    treated as errors' or 'compilation terminated')."""
    from click.testing import CliRunner

    from dopus_codegen.cli import main as cli_main

    folder = tmp_path / "unicycle"
    shutil.copytree(generated["unicycle"][1], folder, ignore=shutil.ignore_patterns("build"))
    with (folder / "unicycle_casadi.c").open("a") as fh:
        fh.write("\nstatic int unused_for_the_test(int a) { return 0; }\n")
    res = CliRunner().invoke(cli_main, ["build", str(folder)])
    assert res.exit_code == 2, res.output
    assert "unicycle_casadi.c:" in res.output and "unused" in res.output, res.output


def test_regenerating_leaves_unchanged_files_alone(second_disc, tmp_path):
    folder = generate(second_disc, tmp_path / "u")
    stamps = {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}
    meta = json.loads((folder / "unicycle_meta.json").read_text())
    (folder / "unicycle_old.c").write_text("int stale;\n")  # a file an earlier generation made
    meta["files"].append("unicycle_old.c")
    (folder / "unicycle_meta.json").write_text(json.dumps(meta))
    generate(second_disc, folder)
    assert not (folder / "unicycle_old.c").exists()
    after = {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}
    assert set(after) == set(stamps)
    assert all(after[f] == stamps[f] for f in stamps if f != "unicycle_meta.json")


def test_generate_refuses_a_foreign_folder(robot_disc, tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(CodegenError, match="not generated by dopus-gen"):
        generate(robot_disc, tmp_path)
    assert (tmp_path / "notes.txt").read_text() == "mine"


# ----------------------------------------------------------------------------------------
# 7. the command line


def test_cli_help_texts():
    runner = CliRunner()
    gen = runner.invoke(cli_main, ["generate", "--help"])
    assert gen.exit_code == 0
    for word in ("OCP_FILE", "generated/<name>", "Makefile", "--offline-guess"):
        assert word in gen.output
    bld = runner.invoke(cli_main, ["build", "--help"])
    assert bld.exit_code == 0
    for word in ("FOLDER", "lib<name>.so", "lib<name>.a", "--cc", "--opt", "-Werror"):
        assert word in bld.output


def test_cli_generate_and_build(generated, tmp_path):
    """The verbs `make generate` uses give the same folder as the Python call."""
    runner = CliRunner()
    out = tmp_path / "unicycle"
    res = runner.invoke(cli_main, ["generate", str(EXAMPLES["unicycle"]), "-o", str(out)])
    assert res.exit_code == 0, res.output
    ref = generated["unicycle"][1]
    for path in sorted(p for p in ref.iterdir() if p.is_file()):
        assert (out / path.name).read_bytes() == path.read_bytes(), path.name
    res = runner.invoke(cli_main, ["build", str(out)])
    assert res.exit_code == 0 and "built:" in res.output and "libunicycle.so" in res.output, res.output
    res = runner.invoke(cli_main, ["build", str(out)])
    assert res.exit_code == 0 and "up to date:" in res.output, res.output


def test_cli_errors(tmp_path):
    runner = CliRunner()
    no_build = tmp_path / "no_build.py"
    no_build.write_text("x = 1\n")
    res = runner.invoke(cli_main, ["generate", str(no_build), "-o", str(tmp_path / "out")])
    assert res.exit_code != 0 and "build()" in res.output and "Traceback" not in res.output

    syntax = tmp_path / "syntax.py"
    syntax.write_text("def build(:\n")
    res = runner.invoke(cli_main, ["generate", str(syntax)])
    assert res.exit_code != 0 and "syntax" in res.output.lower() and "syntax.py" in res.output

    res = runner.invoke(cli_main, ["generate", str(tmp_path / "missing.py")])
    assert res.exit_code != 0 and "missing.py" in res.output

    res = runner.invoke(cli_main, ["build", str(tmp_path / "nowhere")])
    assert res.exit_code != 0 and "does not exist" in res.output and "nowhere" in res.output

    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "a.c").write_text("int a;\n")
    res = runner.invoke(cli_main, ["build", str(plain)])
    assert res.exit_code != 0 and "not a folder generated by dopus-gen" in res.output
    assert "Traceback" not in res.output
