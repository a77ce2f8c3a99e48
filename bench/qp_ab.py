"""Two versions of the C QP solver side by side: a git revision's runtime_c/ (``--base``)
against the working tree's, on the same QPs.

For a change that must not alter the method (a restructuring of dopus_qp.c), it checks
that both give bit for bit the same solution arrays, status, iteration count and every
field of dopus_qp_info (and the same row from dopus_qp_infeasible_row); for a change that
alters the round-off, it reports the answers that both solved with their residuals against
the tolerance and their largest differences, and every status that changed. It times both
builds interleaved on the same QPs (solve only; the data is already in each build's
structures) and reports the ratio of the median time per QP, working tree / base.

QPs: the random QPs of tests/test_qp.py's configurations (tests/harness/qp_problems.py),
each solved cold, warm from its cold solution after a small change of x0, and with
max_iter 3; indefinite and strongly nonconvex ones (inertia correction, restarts);
infeasible and unbounded ones; random QPs of 13 and 21 states (the quadrotor's and the chain
of masses' sizes); the stored robot-arm and unicycle QPs of tests/data; and
(unless --no-bench-qps) the QPs of bench/qp_bench.py: the 26 robot-arm QPs and its random
QPs with the robot's sizes, N = 10 to 160, at tolerance 1e-8.

    .venv/bin/python bench/qp_ab.py --base main           # equality + timing
    .venv/bin/python bench/qp_ab.py --base main --reps 0  # equality only
    .venv/bin/python bench/qp_ab.py --base main --only bench_robot,robot_arm_qp,nx  # a subset

Both builds use the QP test harness (tests/harness/qp_harness.py, its -O3 and strict
flags). Writes bench/results/qp_ab.json.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
sys.path.insert(0, str(ROOT / "tests"))

from harness import qp_harness as H  # noqa: E402
from harness import qp_problems as P  # noqa: E402

DATA = ROOT / "tests" / "data"
# (name, sizes, generator options, count): a subset of tests/test_qp.py's CONFIGS
RANDOM = [
    ("tiny", (2, 1, 1, 0, 0, 0), {}, 10),
    ("small_general", (3, 2, 1, 1, 0, 0), {}, 10),
    ("terminal_rows", (12, 4, 2, 1, 2, 1), {}, 10),
    ("robot_sizes", (40, 5, 3, 0, 0, 2), {"p_active": 0.5}, 10),
    ("many_active", (20, 4, 3, 2, 1, 1), {"p_active": 0.8}, 10),
    ("semidefinite", (15, 4, 2, 1, 1, 1), {"hessian": "psd"}, 10),
    ("badly_scaled", (15, 4, 2, 1, 1, 1), {"var_scale": 1.0, "row_scale": 1.5, "eq_row_scale": 3.0}, 10),
    ("weak", (10, 5, 3, 2, 1, 1), {"p_weak": 0.25}, 10),
    ("nx13", (20, 13, 4, 0, 0, 0), {"p_active": 0.3}, 4),
    ("nx21", (20, 21, 3, 0, 0, 0), {"p_active": 0.3}, 4),
]


def bench_problems(random_per_n: int = 2, warm_chain: bool = False):
    """The QPs of bench/qp_bench.py (robot arm: 20 cold Gauss-Newton, 6 warm exact-Hessian;
    random ones with the robot's sizes), tolerance 1e-8. ``warm_chain``: also each robot-arm
    QP but a run's first warm-started from the previous QP's solution of its run (as
    qp_bench's ``ours_warm``)."""
    import qp_bench as QB

    out = []
    prev: dict = {}
    for tag, qp in QB.robot_arm_qps(20, 6, log=lambda *a: None):
        sz = tuple(int(qp[k]) for k in ("N", "nx", "nu", "ng", "nr", "ne"))
        group = tag.rsplit('_', 1)[0]
        out.append((f"bench_robot_{group}/{tag}", sz, qp, {"tol": 1e-8}))
        if warm_chain and group in prev:
            out.append((f"bench_robot_{group}/{tag}/warm", sz, qp, {"tol": 1e-8, "warm_from": prev[group]}))
        prev[group] = qp
    rng = np.random.default_rng(0)
    for n in QB.RANDOM_NS:
        for t in range(random_per_n):
            qp = QB.random_qp(n, rng)
            sz = tuple(int(qp[k]) for k in ("N", "nx", "nu", "ng", "nr", "ne"))
            out.append((f"bench_random_N{n}/{t}", sz, qp, {"tol": 1e-8}))
    return out


def problems():
    """(label, sizes, qp, solve kwargs) of every case."""
    out = []
    for name, sizes, opts, count in RANDOM:
        rng = np.random.default_rng(zlib.crc32(name.encode()))
        for t in range(count):
            qp, _ = P.make_qp(rng, *sizes, **opts)
            out.append((f"{name}/{t}", sizes, qp, {"tol": 1e-13}))
            out.append((f"{name}/{t}/max_iter3", sizes, qp, {"tol": 1e-13, "max_iter": 3}))
            qp2 = dict(qp)
            qp2["x0"] = qp["x0"] + 1e-3 * rng.standard_normal(qp["x0"].shape)
            out.append((f"{name}/{t}/warm", sizes, qp2, {"tol": 1e-13, "warm_from": qp}))
    rng = np.random.default_rng(1)
    for sizes in [(20, 4, 2, 1, 1, 1), (40, 5, 3, 0, 0, 2)]:
        for t in range(8):
            qp, ref = P.make_qp(rng, *sizes, hessian="indef", p_active=0.4)
            P.make_indefinite(qp, ref)
            out.append((f"indefinite{sizes[0]}/{t}", sizes, qp, {"tol": 1e-13}))
    rng = np.random.default_rng(3)
    for t in range(8):
        qp, _ = P.make_qp(rng, 5, 2, 1, p_active=0.0, p_free=0.0)
        for k in range(5):
            qp["H"][k][2, 2] = -1e3
        out.append((f"nonconvex/{t}", (5, 2, 1, 0, 0, 0), qp, {"tol": 1e-10}))
    sizes = (10, 4, 2, 1, 2, 1)
    for kind in ("row_vs_box", "terminal_eq_vs_box", "terminal_rows"):
        rng = np.random.default_rng(zlib.crc32(kind.encode()))
        for t in range(5):
            out.append((f"infeasible_{kind}/{t}", sizes, P.make_infeasible(rng, *sizes, kind), {"tol": 1e-10}))
    rng = np.random.default_rng(11)
    for t in range(5):
        out.append((f"unbounded/{t}", sizes, P.make_unbounded(rng, *sizes), {"tol": 1e-10}))
    for f in sorted(DATA.glob("*_qp_*.npz")):
        with np.load(f) as z:
            qp = {k: z[k] for k in z.files}
        sz = tuple(int(qp[k]) for k in ("N", "nx", "nu", "ng", "nr", "ne"))
        for tol in (1e-8, 1e-10, 1e-12):
            out.append((f"{f.stem}/tol{tol:g}", sz, qp, {"tol": tol}))
        out.append((f"{f.stem}/lm", sz, qp, {"tol": 1e-12, "hess_shift": 1e-4}))
    return out


def build(rc_dir: Path, sizes, cache: dict):
    key = (str(rc_dir), sizes)
    if key not in cache:
        H.runtime_c_dir = lambda: rc_dir
        cache[key] = H.build_qp_solver(*sizes)
    return cache[key]


def run(h, qp, kw, active_set: int = 0):
    kw = dict(kw)
    warm_from = kw.pop("warm_from", None)
    warm = h.solve(warm_from, tol=kw["tol"])[0] if warm_from is not None else None
    if warm is not None and active_set > 0:
        kw["active_set"] = active_set
    sol, info = h.solve(qp, warm=warm, **kw)
    return sol, info, h.infeasible_row()


def same(a, b) -> bool:
    sa, ia, ra = a
    sb, ib, rb = b
    if ra != rb or set(sa) != set(sb) or set(ia) != set(ib):
        return False
    if any(sa[k].tobytes() != sb[k].tobytes() for k in sa):
        return False
    return all(np.float64(ia[k]).tobytes() == np.float64(ib[k]).tobytes() if isinstance(ia[k], float)
               else ia[k] == ib[k] for k in ia)


def difference(a, b) -> dict:
    """How far apart two answers are: the largest difference of the primal (x, u) and of the
    multipliers (lam, nu and the row multipliers), each relative to 1 + the largest entry of
    the base's, and the largest scaled KKT residual of each."""
    sa, ia, _ = a
    sb, ib, _ = b

    def rel(keys):
        va = np.concatenate([np.ravel(sa[k]) for k in keys])
        vb = np.concatenate([np.ravel(sb[k]) for k in keys])
        return float(np.max(np.abs(va - vb), initial=0.0) / (1.0 + np.max(np.abs(va), initial=0.0)))

    def res(info):
        return max(info[k] for k in ("res_stat_scaled", "res_eq_scaled", "res_ineq_scaled", "res_comp_scaled"))
    return {"primal": rel(("x", "u")), "dual": rel(("lam", "mu_b", "mu_bN", "mu_g", "mu_r", "nu")),
            "res_base": float(res(ia)), "res_work": float(res(ib))}


def time_pair(ha, hb, reps):
    """Median time of the solve call alone, the two builds alternating (order swapped
    every repetition)."""
    ta, tb = [], []
    calls = [(ha, ta), (hb, tb)]
    for r in range(reps):
        for h, acc in (calls if r % 2 == 0 else calls[::-1]):
            t0 = time.perf_counter_ns()
            h.solve_again()
            acc.append(time.perf_counter_ns() - t0)
    return float(np.median(ta)) * 1e-9, float(np.median(tb)) * 1e-9


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", default="main", help="git revision of the base runtime_c/ (default %(default)s)")
    ap.add_argument("--reps", type=int, default=40, help="timed repetitions per QP and build (0: no timing)")
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--no-bench-qps", action="store_true", help="skip bench/qp_bench.py's QPs (robot-arm runs)")
    ap.add_argument("--only", default="", metavar="PREFIX,...",
                    help="only the QPs whose label starts with one of these (e.g. bench_robot,robot_arm_qp,nx)")
    ap.add_argument("--active-set", type=int, default=0, metavar="SWEEPS",
                    help="the warm solves with the active-set start of at most SWEEPS sweeps (settings."
                         "active_set), and the robot-arm QPs also warm-started along their runs (default 0: off)")
    ap.add_argument("--json", type=Path, default=BENCH / "results" / "qp_ab.json")
    args = ap.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="qp_ab_"))
    base_dir = tmp / "runtime_c"
    arch = subprocess.run(["git", "-C", str(ROOT), "archive", args.base, "runtime_c"],
                          check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tmp)], input=arch, check=True)
    work_dir = ROOT / "runtime_c"
    cache: dict = {}
    rows, mismatches = [], []
    cases = problems() + ([] if args.no_bench_qps else bench_problems(warm_chain=args.active_set > 0))
    if args.only:
        cases = [c for c in cases if c[0].startswith(tuple(args.only.split(",")))]
    for label, sizes, qp, kw in cases:
        ha, hb = build(base_dir, sizes, cache), build(work_dir, sizes, cache)
        a, b = run(ha, qp, kw, args.active_set), run(hb, qp, kw, args.active_set)
        ok = same(a, b)
        if not ok:
            mismatches.append(label)
        row = {"qp": label, "identical": ok, "status": b[1]["status"], "iterations": b[1]["iterations"],
               "status_base": a[1]["status"], "iterations_base": a[1]["iterations"],
               "active_set": b[1]["active_set"], "active_set_base": a[1]["active_set"],
               "factorizations": b[1]["factorizations"], "factorizations_base": a[1]["factorizations"],
               "tol": kw["tol"], **({} if ok else difference(a, b))}
        if args.reps > 0 and "warm_from" not in kw and kw.get("max_iter", 100) > 3:
            time_pair(ha, hb, args.warmup)
            row["t_base"], row["t_work"] = time_pair(ha, hb, args.reps)
            row["ratio"] = row["t_work"] / row["t_base"]
        rows.append(row)
    statuses: dict = {}
    statuses_base: dict = {}
    for r in rows:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
        statuses_base[r["status_base"]] = statuses_base.get(r["status_base"], 0) + 1
    print(f"{len(rows)} solves, base {args.base} vs working tree: {len(rows) - len(mismatches)} bit-identical, "
          f"{len(mismatches)} differ {mismatches[:10]}")
    print("statuses base:", statuses_base, " iterations total:", sum(r["iterations_base"] for r in rows))
    print("statuses work:", statuses, " iterations total:", sum(r["iterations"] for r in rows))
    differ = [r for r in rows if not r["identical"]]
    solved = [r for r in differ if r["status"] == r["status_base"] == "solved"]
    if solved:
        # answers that are not bit-identical but both solved: equal to the QP's tolerance
        # when both meet it (the accuracy of the answer is the tolerance over the QP's
        # conditioning, dopus_qp.h), with the largest differences of the answers
        print(f"{len(solved)} of them solved by both: work residuals within tol in "
              f"{sum(r['res_work'] <= r['tol'] for r in solved)}, base in "
              f"{sum(r['res_base'] <= r['tol'] for r in solved)}; largest difference primal "
              f"{max(r['primal'] for r in solved):.1e}, multipliers {max(r['dual'] for r in solved):.1e} "
              f"(relative to 1 + the base's largest entry); median {np.median([r['primal'] for r in solved]):.1e}, "
              f"{np.median([r['dual'] for r in solved]):.1e}")
    started = [r for r in rows if r["active_set"] > 0 or r["active_set_base"] > 0]
    if args.active_set > 0:
        # the solves the active-set start answered (info.active_set: its sweeps) in either build
        print(f"active-set start: solved {sum(r['active_set'] > 0 for r in rows)} (base "
              f"{sum(r['active_set_base'] > 0 for r in rows)}); of these the same sweeps in "
              f"{sum(r['active_set'] == r['active_set_base'] for r in started)} of {len(started)}, the same "
              f"factorisations in {sum(r['factorizations'] == r['factorizations_base'] for r in started)}")
    changed = [r for r in differ if r["status"] != r["status_base"]]
    print(f"status changed in {len(changed)}: " + ", ".join(f"{r['qp']} {r['status_base']} -> {r['status']}"
                                                       for r in changed))
    if differ and len(differ) <= 40:
        w = max(len(r["qp"]) for r in differ)
        print(f"{'QP that differs':{w}s} {'status base':>18s} {'it':>4s} {'status work':>18s} {'it':>4s}")
        for r in differ:
            print(f"{r['qp']:{w}s} {r['status_base']:>18s} {r['iterations_base']:4d} {r['status']:>18s} "
                  f"{r['iterations']:4d}")
    timed = [r for r in rows if "ratio" in r]
    summary = {"base": args.base, "solves": len(rows), "identical": len(rows) - len(mismatches),
               "mismatches": mismatches, "statuses": statuses, "statuses_base": statuses_base,
               "active_set": args.active_set}
    if timed:
        w = max(len(r["qp"].split("/")[0]) for r in timed)
        print(f"{'group':{w}s} {'QPs':>4s} {'t_base us':>10s} {'t_work us':>10s} {'median ratio':>13s} "
              f"{'geomean':>8s}")
        groups: dict = {}
        for r in timed:
            groups.setdefault(r["qp"].split("/")[0], []).append(r)
        groups["ALL"] = timed
        summary["groups"] = {}
        for g, rs in groups.items():
            ratios = np.array([r["ratio"] for r in rs])
            tb, tw = np.median([r["t_base"] for r in rs]), np.median([r["t_work"] for r in rs])
            gm = float(np.exp(np.mean(np.log(ratios))))
            print(f"{g:{w}s} {len(rs):4d} {tb * 1e6:10.1f} {tw * 1e6:10.1f} {np.median(ratios):13.3f} {gm:8.3f}")
            summary["groups"][g] = {"qps": len(rs), "median_ratio": float(np.median(ratios)), "geomean_ratio": gm}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    return 1 if mismatches else 0


if __name__ == "__main__":
    sys.exit(main())
