"""Structured integrator sensitivities, warning-free CasADi C and the build cache.

- The stage functions iterate one substep and its derivative kernels
  (dopus_codegen.problem.sensitivities); their blocks are compared with CasADi's SX
  derivatives of the unrolled interval map (the former construction), for every way of
  treating the seed directions.
- The generated CasADi file compiles under the project's strict flags.
- A second generate + build of an unchanged problem compiles nothing; another folder of
  the same problem gets every object from the build cache.
"""
from __future__ import annotations

import dataclasses
import os
import subprocess

import casadi as ca
import numpy as np
import pytest

from conftest import EXAMPLES, ROBOT_ARM_FILE, SECOND_FILE
from dopus_codegen.codegen.build import build
from dopus_codegen.codegen.generate import STRICT_CFLAGS, generate, read_meta, silence_unused_parameters
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.problem.ocp import RK4, load_ocp

CHAIN_FILE = EXAMPLES / "chain.py"


def _with_integrator(spec, integrator):
    return dataclasses.replace(spec, model=dataclasses.replace(spec.model, integrator=integrator))


def _unrolled_reference(spec):
    """phi, Phi, grad and Hessian of -lam' phi from the unrolled SX expression."""
    x, u, p = spec.model.x, spec.model.u, spec.model.p
    w = ca.vertcat(x, u)
    ode = ca.Function("ode", [x, u, p], [spec.model.xdot])
    phi = spec.model.integrator.step(ode, x, u, p, spec.horizon.dt)
    lam = ca.SX.sym("lam", x.size1())
    L = -ca.dot(lam, phi)
    return ca.Function("ref", [x, u, p, lam], [phi, ca.jacobian(phi, w), ca.gradient(L, w),
                                               ca.hessian(L, w)[0]])


@pytest.mark.parametrize("path,derivatives,directions", [
    (ROBOT_ARM_FILE, "structured", "auto"), (ROBOT_ARM_FILE, "structured", "one"),
    (ROBOT_ARM_FILE, "structured", 2), (SECOND_FILE, "structured", "all"),
    (ROBOT_ARM_FILE, "unrolled", "auto"), (ROBOT_ARM_FILE, "chained", "auto"), (SECOND_FILE, "chained", "auto"),
    (CHAIN_FILE, "auto", "auto")])
def test_structured_blocks_equal_the_unrolled_derivatives(path, derivatives, directions):
    spec = load_ocp(path).validate()
    spec = _with_integrator(spec, RK4(spec.model.integrator.substeps, derivatives=derivatives,
                                      directions=directions))
    disc = build_functions(spec)
    want = "SXFunction" if derivatives == "unrolled" else "MXFunction"
    assert disc.stage_hess_exact.class_name() == want
    ref = _unrolled_reference(spec)
    rng = np.random.default_rng(3)
    g = disc.initial_guess
    for k in (0, disc.N // 2):
        x = g.x[k] + 0.02 * rng.standard_normal(disc.nx)
        u = g.u[k] + 0.1 * rng.standard_normal(disc.nu)
        p = disc.p0[k]
        lam, mu_g = rng.standard_normal(disc.nx), rng.standard_normal(disc.ng)
        phi_r, Phi_r, g_r, H_r = (np.array(v) for v in ref(x, u, p, lam))
        gL, phi, l, gk = (np.array(v) for v in disc.stage_grad(x, u, p, lam, mu_g))
        gL0 = np.array(disc.stage_grad(x, u, p, np.zeros(disc.nx), mu_g)[0])
        A, Phi, C = (np.array(v) for v in disc.stage_hess_exact(x, u, p, lam, mu_g))
        A0 = np.array(disc.stage_hess_exact(x, u, p, np.zeros(disc.nx), mu_g)[0])
        scale = 1 + np.abs(H_r).max()
        np.testing.assert_allclose(phi.ravel(), phi_r.ravel(), rtol=0, atol=1e-13 * (1 + np.abs(phi_r).max()))
        np.testing.assert_allclose(Phi, Phi_r, rtol=0, atol=1e-12 * (1 + np.abs(Phi_r).max()))
        # the dynamics part: the stage function with lam minus the same with lam = 0
        np.testing.assert_allclose((gL - gL0).ravel(), g_r.ravel(), rtol=0,
                                   atol=1e-12 * (1 + np.abs(g_r).max()))
        np.testing.assert_allclose(A - A0, 0.5 * (H_r + H_r.T), rtol=0, atol=1e-12 * scale)
        np.testing.assert_array_equal(A, A.T)
        if disc.stage_hess_gn is not None:
            _, Phi_gn, _ = (np.array(v) for v in disc.stage_hess_gn(x, u, p, lam, mu_g))
            np.testing.assert_array_equal(Phi_gn, Phi)


@pytest.mark.parametrize("derivatives", ["default", "chained"])
def test_hessian_by_finite_differences_of_the_gradient(robot_disc, derivatives):
    """Independent of CasADi's second derivatives: central differences of stage_grad."""
    d = robot_disc
    if derivatives != "default":
        spec = load_ocp(ROBOT_ARM_FILE).validate()
        d = build_functions(_with_integrator(spec, RK4(spec.model.integrator.substeps, derivatives=derivatives)))
    rng = np.random.default_rng(5)
    x, u, p = d.initial_guess.x[3], d.initial_guess.u[3] + 0.3, d.p0[3]
    lam, mu_g = rng.standard_normal(d.nx), rng.standard_normal(d.ng)
    w = np.concatenate([x, u])
    A = np.array(d.stage_hess_exact(x, u, p, lam, mu_g)[0])
    h = 1e-5
    fd = np.zeros_like(A)
    for j in range(d.nw):
        e = np.zeros(d.nw)
        e[j] = h
        gp = np.array(d.stage_grad((w + e)[:d.nx], (w + e)[d.nx:], p, lam, mu_g)[0]).ravel()
        gm = np.array(d.stage_grad((w - e)[:d.nx], (w - e)[d.nx:], p, lam, mu_g)[0]).ravel()
        fd[:, j] = (gp - gm) / (2 * h)
    np.testing.assert_allclose(A, fd, rtol=0, atol=1e-6 * (1 + np.abs(A).max()))


def test_generated_casadi_file_is_warning_free_under_strict_flags(tmp_path, second_disc):
    generate(second_disc, tmp_path / "u")
    src = tmp_path / "u" / "unicycle_casadi.c"
    proc = subprocess.run(["cc", *STRICT_CFLAGS, "-c", str(src), "-o", str(tmp_path / "c.o")],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert proc.returncode == 0, proc.stdout
    assert proc.stdout == ""


def test_unused_parameters_are_marked_only_where_unused(tmp_path):
    text = ("static int f(const double* x, double* y, int mem) {\n  y[0] = x[0];\n  return 0;\n}\n\n"
            "void g(int mem) {\n}\n\nint h(void) {\n  double y[1];\n  const double x[1] = {1.0};\n  return f(x, y, 0);\n}\n")
    out = silence_unused_parameters(text)
    assert "  (void)mem;" in out.splitlines()[1]
    assert "(void)x" not in out and "(void)y" not in out
    src = tmp_path / "s.c"
    src.write_text(out)
    proc = subprocess.run(["cc", *STRICT_CFLAGS, "-c", str(src), "-o", str(tmp_path / "s.o")],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert proc.returncode == 0, proc.stdout


def test_second_generate_and_build_compile_nothing(tmp_path, second_disc):
    cache_dir = tmp_path / "cache"
    folder = tmp_path / "u"
    generate(second_disc, folder)
    first = build(folder, cache_dir=cache_dir, echo=None)
    sources = read_meta(folder)["sources"]
    # every library source compiled once (the standalone main program is not in the library)
    assert first.rebuilt and sorted(first.compiled) == sorted([*sources["strict"], sources["casadi"]])
    stamps = {p.name: p.stat().st_mtime_ns for p in folder.iterdir() if p.is_file()}
    # the same problem again, discretised anew: nothing is written or compiled
    disc2 = build_functions(load_ocp(SECOND_FILE))
    generate(disc2, folder)
    assert {p.name: p.stat().st_mtime_ns for p in folder.iterdir() if p.is_file()} == stamps
    second = build(folder, cache_dir=cache_dir, echo=None)
    assert not second.rebuilt and second.compiled == []
    # another folder of the same problem: every object comes from the cache
    other = generate(disc2, tmp_path / "v")
    third = build(other, cache_dir=cache_dir, echo=None)
    assert third.rebuilt and third.compiled == []
    # the folder's Makefile finds everything built: `make` only links the main program
    proc = subprocess.run(["make", "-n", "-C", str(folder), "lib"], stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True)
    assert proc.returncode == 0 and " -c " not in proc.stdout, proc.stdout


def test_cache_location_from_the_environment(tmp_path, monkeypatch):
    from dopus_codegen.codegen.cache import cache_root

    monkeypatch.setenv("DOPUS_CACHE_DIR", str(tmp_path / "c"))
    assert cache_root() == tmp_path / "c"
    assert cache_root(tmp_path / "d") == tmp_path / "d"
    monkeypatch.delenv("DOPUS_CACHE_DIR")
    assert cache_root() == type(tmp_path).home() / ".cache" / "dopus-codegen"
    assert os.environ.get("DOPUS_CACHE_DIR") is None


@pytest.mark.parametrize("path", [SECOND_FILE, CHAIN_FILE])
def test_compact_functions_compute_the_same_values(path):
    """The emitted (compact) functions against the problem's own: constant SX functions
    become static arrays, an SX function equal to one emitted before a call to it."""
    from dopus_codegen.codegen.generate import casadi_functions, problem_sizes

    disc = build_functions(load_ocp(path))
    emitted = casadi_functions(disc, disc.name, problem_sizes(disc))
    rng = np.random.default_rng(11)
    compacted = 0
    for slot, fun in emitted.items():
        orig = getattr(disc.functions, slot)
        compacted += orig.class_name() != fun.class_name()
        args = [rng.standard_normal(orig.sparsity_in(i).shape) for i in range(orig.n_in())]
        for want, got in zip(orig(*args) if orig.n_out() > 1 else [orig(*args)],
                             fun(*args) if fun.n_out() > 1 else [fun(*args)]):
            np.testing.assert_array_equal(np.array(got), np.array(want))
    # unicycle: constant stage and terminal cost Hessians; chain: the same, and the
    # Gauss-Newton forms equal to the exact ones
    assert compacted >= 2


def test_parallel_compilations_from_the_environment(monkeypatch):
    from dopus_codegen.codegen.build import BuildError, build_jobs

    monkeypatch.setenv("DOPUS_BUILD_JOBS", "3")
    assert build_jobs(10) == 3 and build_jobs(2) == 2
    for bad in ("0", "two"):
        monkeypatch.setenv("DOPUS_BUILD_JOBS", bad)
        with pytest.raises(BuildError, match="DOPUS_BUILD_JOBS"):
            build_jobs(4)
    monkeypatch.delenv("DOPUS_BUILD_JOBS")
    assert 1 <= build_jobs(10) <= 10
