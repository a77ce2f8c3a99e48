"""Integrator sensitivities that keep the integrator's structure.

The interval map is ``phi = F o F o ... o F`` (``n`` substeps of one substep map
``F(x, u, p)``). Instead of one expression of ``phi`` and its derivatives (whose size
grows with the number of substeps and, for second derivatives, with ``nw`` times the
model), everything here is built from four small kernels of one substep, each a CasADi
function of its own, called once per substep from an MX graph:

- ``F``:    ``(x, u, p) -> x+``
- ``fwd``:  ``((x, u, p), dx, du) -> dx+``               forward derivative, ``d`` directions
- ``adj``:  ``((x, u, p, a)) -> (F_x' a, F_u' a)``        adjoint
- ``soa``:  ``((x, u, p, a), dx, du, da) -> d(F_x' a, F_u' a)``  forward over adjoint

A kernel with one direction is mapped over the ``nw`` directions with
``Function.map(nw, "serial")``, which CasADi's code generator emits as a C loop, so the
generated code holds each kernel once: its size does not grow with the number of
substeps (each substep adds one call site) and grows with ``nw`` only through loop
counts. With ``directions="all"`` the kernels take all ``nw`` directions at once (one
vectorised expression with common subexpressions shared): larger code, fewer calls; it
pays off for small models.

Propagation over ``w = (x, u)`` of the interval (``E = [0 I]`` selects ``u``):

- forward (Gauss-Newton blocks, ``Phi``): ``S_0 = [I 0]``, ``S_{j+1} = F_x S_j + F_u E``;
- adjoint (gradient of ``a_n' x_n``): ``a_j = F_x(z_j)' a_{j+1}``, ``g_u += F_u(z_j)' a_{j+1}``;
- forward over adjoint (Hessian of ``a_n' x_n``, ``a_n`` fixed): differentiating the adjoint
  recursion along the ``nw`` seeds gives ``D_n = 0``,
  ``(D_j, G_u += ...) = soa(z_j, a_{j+1}, S_j, E, D_{j+1})`` and the Hessian ``[D_0; G_u]``.

For small models a third way (``derivatives="chained"``, :func:`chain_kernel`,
:func:`chain_hessian`) keeps the unit seeds of the substep constant, so CasADi exploits the
substep's sparsity: one kernel returns the substep's Jacobian, adjoint and Hessian, and the
Hessian of the interval is chained from them substep by substep (``G_j = H_j + T_j' G_{j+1}
T_j``), at about the operation count of the unrolled expression with the code of one substep.

Every kernel is exact (CasADi's algorithmic differentiation of the substep), so the blocks
equal those of the unrolled expression to round-off. An implicit substep (an MX function
with a rootfinder) gets its kernels the same way; CasADi then differentiates the
rootfinder by the implicit function theorem.
"""
from __future__ import annotations

from typing import Optional

import casadi as ca

__all__ = ["SubstepKernels", "substep_kernels", "propagate_forward", "propagate_adjoint",
           "interval_map", "interval_map_inlined", "adjoint_inlined", "hessian_inlined",
           "DIRECTION_MODES", "chain_kernel", "chain_hessian"]

_SX_OPTS = {"cse": True}

#: "one": one-direction kernels mapped in a loop; "all": all directions in one kernel;
#: "auto": the largest chunk of directions whose kernel stays small (see substep_kernels).
DIRECTION_MODES = ("auto", "one", "all")

# "auto" chooses the vectorised kernels while their forward-over-adjoint kernel stays
# below this many SX instructions (robot arm: 6882; chain of masses: 51768).
_AUTO_LIMIT = 12000


class SubstepKernels:
    """The four kernels of one substep (see the module docstring) and their mapped forms."""

    def __init__(self, F, fwd, adj, soa, nx, nu, np_, nd):
        self.F, self.fwd, self.adj, self.soa = F, fwd, adj, soa
        self.nx, self.nu, self.np, self.nd = nx, nu, np_, nd
        nw = nx + nu
        if nd == nw:
            self.fwd_w, self.soa_w = fwd, soa
        else:
            self.fwd_w = fwd.map(nw // nd, "serial")
            self.soa_w = soa.map(nw // nd, "serial")


def _sym(kind, name, n, m=1):
    return kind.sym(name, n, m)


def _build(prefix: str, F: ca.Function, nx: int, nu: int, np_: int, nd: int):
    is_sx = F.is_a("SXFunction")
    T = ca.SX if is_sx else ca.MX
    opts = _SX_OPTS if is_sx else {}
    x, u, p = _sym(T, "x", nx), _sym(T, "u", nu), _sym(T, "p", np_)
    a = _sym(T, "a", nx)
    dx, du, da = _sym(T, "dx", nx, nd), _sym(T, "du", nu, nd), _sym(T, "da", nx, nd)
    z = ca.vertcat(x, u)
    xn = F(x, u, p)
    fwd_e = ca.jtimes(xn, z, ca.vertcat(dx, du))
    adj_e = ca.jtimes(xn, z, a, True)
    soa_e = ca.jtimes(adj_e, ca.vertcat(z, a), ca.vertcat(dx, du, da))
    # The point (x, u, p[, a]) is one stacked input: the map over directions repeats it
    # for every call, and an empty p would otherwise be repeated as an empty matrix (for
    # which CasADi 3.8 emits an ill-typed copy).
    zp, zpa = ca.vertcat(x, u, p), ca.vertcat(x, u, p, a)
    fwd = ca.Function(f"{prefix}_fwd", [zp, dx, du], [fwd_e], ["xup", "dx", "du"], ["dxn"], opts)
    adj = ca.Function(f"{prefix}_adj", [zpa], [adj_e[:nx], adj_e[nx:]], ["xupa"], ["ax", "au"], opts)
    soa = ca.Function(f"{prefix}_soa", [zpa, dx, du, da], [soa_e[:nx, :], soa_e[nx:, :]],
                      ["xupa", "dx", "du", "da"], ["dax", "dau"], opts)
    return fwd, adj, soa


def _divisor(nw: int, nd: int) -> int:
    """The largest divisor of nw that is <= nd (the map needs equal chunks)."""
    nd = max(1, min(int(nd), nw))
    while nw % nd:
        nd -= 1
    return nd


def substep_kernels(prefix: str, F: ca.Function, nx: int, nu: int, np_: int,
                    directions="auto") -> SubstepKernels:
    """The kernels of the substep map ``F: (x, u, p) -> x+`` (SX or MX function).

    ``directions``: how many of the ``nw`` seed directions one kernel call takes: an
    integer (rounded down to a divisor of ``nw``), ``"one"`` (1), ``"all"`` (``nw``) or
    ``"auto"``: ``nw`` if that forward-over-adjoint kernel stays below ``_AUTO_LIMIT`` SX
    instructions, else 1 (an MX substep: 1). Measured on the robot arm (nw = 8): all
    directions at once make the Hessian phase about 2x faster than the unrolled expression
    and the one-direction loop about 3.5x slower (the loop's code is 3x smaller).
    """
    nw = nx + nu
    if directions == "one":
        nd = 1
    elif directions == "all":
        nd = nw
    elif directions == "auto":
        nd = 1
        if F.is_a("SXFunction"):
            fwd, adj, soa = _build(prefix, F, nx, nu, np_, nw)
            if soa.n_instructions() <= _AUTO_LIMIT:
                return SubstepKernels(F, fwd, adj, soa, nx, nu, np_, nw)
    elif isinstance(directions, (int,)) and not isinstance(directions, bool) and directions >= 1:
        nd = _divisor(nw, directions)
    else:
        raise ValueError(f"directions must be 'auto', 'one', 'all' or an integer >= 1, got {directions!r}")
    fwd, adj, soa = _build(prefix, F, nx, nu, np_, nd)
    return SubstepKernels(F, fwd, adj, soa, nx, nu, np_, nd)


def _E(nx: int, nu: int) -> ca.DM:
    """Seeds of u along the nw directions of w: [0 I]."""
    return ca.DM(ca.horzcat(ca.DM.zeros(nu, nx), ca.DM.eye(nu)))


def interval_map(K: SubstepKernels, n: int, x, u, p) -> list:
    """``[x_0, x_1, ..., x_n]`` along the interval (MX)."""
    xs = [x]
    for _ in range(n):
        xs.append(K.F(xs[-1], u, p))
    return xs


def interval_map_inlined(F: ca.Function, n: int, x, u, p):
    """``x_n`` of the interval with the graph of the (MX) substep ``F`` inlined at every
    substep, so that the rootfinder calls of an implicit substep are nodes of one graph."""
    xn = x
    for _ in range(n):
        xn = F.call([xn, u, p], True, False)[0]
    return xn


def adjoint_inlined(xn, x, u, a_n):
    """``d(a_n' x_n)/dw`` by reverse mode on the inlined graph of ``x_n``
    (:func:`interval_map_inlined`): each rootfinder call's derivative takes the stages the
    call computed (implicit function theorem at them) instead of solving again."""
    return ca.jtimes(xn, ca.vertcat(x, u), a_n, True)


def hessian_inlined(xn, g, x, u):
    """``(Phi, H)`` on the inlined graph: ``Phi = d x_n / d w`` and ``H = d g / d w`` with ``g``
    the adjoint of :func:`adjoint_inlined` (forward over reverse)."""
    w = ca.vertcat(x, u)
    return ca.jacobian(xn, w), ca.jacobian(g, w)


def propagate_forward(K: SubstepKernels, xs: list, u, p) -> list:
    """``[S_0, ..., S_n]``: ``S_j = d x_j / d w`` (nx x nw)."""
    nx, nu = K.nx, K.nu
    S = [ca.MX(ca.horzcat(ca.DM.eye(nx), ca.DM.zeros(nx, nu)))]
    E = ca.MX(_E(nx, nu))
    for j in range(len(xs) - 1):
        S.append(K.fwd_w(ca.vertcat(xs[j], u, p), S[j], E))
    return S


def propagate_adjoint(K: SubstepKernels, xs: list, u, p, a_n, S: Optional[list] = None):
    """Adjoint sweep of ``a_n' x_n`` from the last substep back.

    Returns ``(g, H)``: ``g = d(a_n' x_n)/dw`` (nw), and with ``S`` (the forward
    sensitivities) the Hessian ``H = d^2(a_n' x_n)/dw^2`` (nw x nw, ``a_n`` fixed), else None.
    """
    nx, nu = K.nx, K.nu
    nw = nx + nu
    n = len(xs) - 1
    a = a_n
    gu = ca.MX.zeros(nu)
    D = ca.MX.zeros(nx, nw) if S is not None else None
    Gu = ca.MX.zeros(nu, nw) if S is not None else None
    E = ca.MX(_E(nx, nu))
    for j in reversed(range(n)):
        zpa = ca.vertcat(xs[j], u, p, a)
        ax, au = K.adj(zpa)
        if S is not None:
            dax, dau = K.soa_w(zpa, S[j], E, D)
            D = dax
            Gu = Gu + dau
        a = ax
        gu = gu + au
    g = ca.vertcat(a, gu)
    H = ca.vertcat(D, Gu) if S is not None else None
    return g, H


def chain_kernel(prefix: str, F: ca.Function, nx: int, nu: int, np_: int) -> ca.Function:
    """One substep and its first and second derivatives at once, for Hessians by chaining
    the substeps (:func:`chain_hessian`): ``xupa = (x, u, p, a) -> (x+, F_x, F_u, F_x' a,
    F_u' a, H)`` with ``H`` the Hessian of ``a' F`` over ``z = (x, u)`` (dense). The seeds
    are the constant unit directions of ``z``, so CasADi's differentiation keeps the
    sparsity of the substep (unlike the symbolic seeds of the forward-over-adjoint kernels)."""
    is_sx = F.is_a("SXFunction")
    T = ca.SX if is_sx else ca.MX
    x, u, p, a = T.sym("x", nx), T.sym("u", nu), T.sym("p", np_), T.sym("a", nx)
    z = ca.vertcat(x, u)
    xn = F(x, u, p)
    J = ca.jacobian(xn, z)
    H, g = ca.hessian(ca.dot(a, xn), z)
    d = ca.densify
    return ca.Function(f"{prefix}_chain", [ca.vertcat(x, u, p, a)],
                       [d(xn), d(J[:, :nx]), d(J[:, nx:]), d(g[:nx]), d(g[nx:]), d(H)], ["xupa"],
                       ["xn", "Jx", "Ju", "ax", "au", "H"], _SX_OPTS if is_sx else {})


def chain_hessian(K: ca.Function, F: ca.Function, n: int, x, u, p, a_n):
    """``(x_n, Phi, g, H)`` of ``a_n' x_n`` over ``w = (x_0, u)`` by Jacobian chaining.

    With ``T_j = [[F_x, F_u], [0, I]]`` the Jacobian of ``z_j -> z_{j+1}``, the Hessian of
    the interval is accumulated from the last substep back:
    ``G_{n-1} = H_{n-1}``, ``G_j = H_j + T_j' G_{j+1} T_j`` (``H_j``: the Hessian of
    ``a_{j+1}' F`` at ``z_j``, ``a_j = F_x' a_{j+1}``), ``H = G_0``; likewise
    ``Phi = d x_n / d w`` and the gradient ``g``. The forward pass evaluates ``F`` for the
    first ``n - 1`` substeps; each substep then calls ``K`` (:func:`chain_kernel`) once."""
    nx = x.size1()
    xs = [x]
    for _ in range(n - 1):
        xs.append(F(xs[-1], u, p))
    a, gu = a_n, None
    xn = G = Px = Pu = None
    for j in reversed(range(n)):
        x_next, Jx, Ju, ax, au, Hj = K(ca.vertcat(xs[j], u, p, a))
        if G is None:
            xn, G, Px, Pu, gu = x_next, Hj, Jx, Ju, au
        else:
            Gx, Gu = G[:, :nx], G[:, nx:]
            GT = ca.horzcat(ca.mtimes(Gx, Jx), ca.mtimes(Gx, Ju) + Gu)
            G = Hj + ca.vertcat(ca.mtimes(Jx.T, GT[:nx, :]), ca.mtimes(Ju.T, GT[:nx, :]) + GT[nx:, :])
            Px, Pu = ca.mtimes(Px, Jx), ca.mtimes(Px, Ju) + Pu
            gu = gu + au
        a = ax
    return xn, ca.horzcat(Px, Pu), ca.vertcat(a, gu), G
