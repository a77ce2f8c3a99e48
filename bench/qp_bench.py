"""QP benchmark: our stage-wise QP solver against HPIPM, in one process, same tolerance.

Solves the same QPs with ``runtime_c/dopus_qp.c`` and with HPIPM through its C API
(``d_ocp_qp_ipm_solve``), both linked into one C program (bench/qp_bench_main.c) that
interleaves the repetitions solver by solver after warm-up runs and reports medians:

* robot-arm QPs: the QP of the current iterate (``ReferenceDopus.qp_of_current``) along
  the cold Gauss-Newton run (OCP file's guess) and the warm exact-Hessian run (converged
  solution, disturbed initial state), full RTI, fixed xhat_0;
* random QPs with the robot's sizes (nx = 5, nu = 3, 3 control bounds, 2 terminal
  equality rows) at N = 10, 20, 40, 80, 160.

The HPIPM anchor is the HPIPM + BLASFEO (X64_INTEL_HASWELL) build of the PyPI wheel
comma-deps-acados, installed by bench/setup_hpipm.sh into its own virtualenv
(bench/.env) so that the wheel's stripped CasADi never shadows the project's; only its C
headers and shared libraries are used here. The HPIPM inside the casadi wheel (generic
BLASFEO target) is reported as a second, non-anchor column when available.

HPIPM configurations (each a column; HPIPM_CONFIGS below, bench/README.md explains them):
``hpipm`` is the QP as stated (mode balance, x0 as a box with lb = ub, the terminal
equality as general rows with lg = ug, as acados does); ``hpipm_eqmask`` adds HPIPM's
equality mask; ``hpipm_robust``, ``hpipm_speed_abs`` other modes; on the robot arm
``hpipm_classic`` uses the classic Riccati recursion and ``hpipm_scaled`` is RESCALED BY
HAND (classic Riccati, terminal equality rows divided by ``--eq-scale`` times their largest
entry), the configuration that converges on every robot-arm QP. ``hpipm_best`` is per QP
the fastest anchor configuration that converged to the tolerance.

Never a pass/fail on time: this prints tables and writes bench/results/qp_bench.json.

    python bench/qp_bench.py                    # everything (a few minutes on a busy machine)
    python bench/qp_bench.py --quick            # fewer repetitions, smoke run
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from dopus_codegen import vocabulary
from dopus_codegen.cnames import rename_placeholder
from dopus_codegen.codegen.flags import CASADI_CFLAGS, DEFAULT_OPT, STRICT_CFLAGS
from dopus_codegen.codegen.generate import render_sizes_header

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
RUNTIME = ROOT / "runtime_c"
RESULTS = BENCH / "results"
BUILD = RESULTS / "build"
ENV = Path(os.environ.get("BENCH_ENV", BENCH / ".env"))

NX, NU, NE = 5, 3, 2           # the robot arm's sizes (docs/robot_arm.md)
RANDOM_NS = (10, 20, 40, 80, 160)
HPIPM_MODES = {"speed_abs": 0, "speed": 1, "balance": 2, "robust": 3}
HPIPM_STATUS = {0: "success", 1: "max_iter", 2: "min_step", 3: "nan", 4: "inconsistent_eq"}
DOPUS_STATUS = {code: name for name, code in vocabulary.qp_status().codes.items()}
# HPIPM configurations, one column each; the first is the anchor ("as stated").
# ric_alg -1 keeps the mode's default (square-root Riccati, which needs every Riccati
# matrix P_k > 0); 0 is the classic Riccati recursion (only the reduced Hessian must be > 0).
HPIPM_CONFIGS = {
    "hpipm": {"mode": "balance", "eq_mask": 0, "eq_scale": False, "ric_alg": -1,
              "what": "acados' default mode (balance); x0 and the terminal equality as rows with lb = ub"},
    "hpipm_eqmask": {"mode": "balance", "eq_mask": 1, "eq_scale": False, "ric_alg": -1,
                     "what": "as hpipm, rows declared in HPIPM's equality mask (idxbxe, idxge)"},
    "hpipm_robust": {"mode": "robust", "eq_mask": 0, "eq_scale": False, "ric_alg": -1,
                     "what": "as hpipm in mode robust"},
    "hpipm_speed_abs": {"mode": "speed_abs", "eq_mask": 0, "eq_scale": False, "ric_alg": -1,
                        "what": "as hpipm in mode speed_abs (exits on the duality measure only)"},
    "hpipm_speed": {"mode": "speed", "eq_mask": 0, "eq_scale": False, "ric_alg": -1,
                    "what": "as hpipm in mode speed"},
    "hpipm_classic": {"mode": "balance", "eq_mask": 0, "eq_scale": False, "ric_alg": 0, "robot_only": True,
                      "what": "as hpipm with the classic Riccati recursion, equality rows as stated"},
    "hpipm_scaled": {"mode": "balance", "eq_mask": 0, "eq_scale": True, "ric_alg": 0, "robot_only": True,
                     "what": "RESCALED BY HAND: terminal equality rows divided by eq_scale * max|row|, "
                             "classic Riccati; the configuration found to converge on the robot-arm QPs"},
    # the same rescaled rows and classic recursion in HPIPM's other modes (acados at its best)
    "hpipm_speed_abs_scaled": {"mode": "speed_abs", "eq_mask": 0, "eq_scale": True, "ric_alg": 0, "robot_only": True,
                               "what": "as hpipm_scaled in mode speed_abs"},
    "hpipm_speed_scaled": {"mode": "speed", "eq_mask": 0, "eq_scale": True, "ric_alg": 0, "robot_only": True,
                           "what": "as hpipm_scaled in mode speed"},
    "hpipm_robust_scaled": {"mode": "robust", "eq_mask": 0, "eq_scale": True, "ric_alg": 0, "robot_only": True,
                            "what": "as hpipm_scaled in mode robust"},
}
# ratio columns (numerator, denominator)
RANDOM_RATIOS = [("ours", "hpipm"), ("ours", "hpipm_best"), ("ours_alt", "hpipm_best")]
ROBOT_RATIOS = [("ours", "hpipm"), ("ours", "hpipm_scaled"), ("ours", "hpipm_best"),
                ("ours_alt", "hpipm_scaled"), ("ours_alt", "hpipm_best"), ("ours_warm", "hpipm_best")]
HARNESS_SOURCES = ("qp_bench_main.c", "qp_bench_qp.c", "qp_bench_hpipm.c")


class BenchError(RuntimeError):
    pass


# ---------------------------------------------------------------------------- HPIPM builds
def _site_packages(env: Path) -> Path:
    hits = sorted(env.glob("lib/python3*/site-packages"))
    if not hits:
        raise BenchError(f"no site-packages under {env}")
    return hits[0]


def ensure_bench_env() -> None:
    """Create bench/.env with bench/setup_hpipm.sh when the anchor is not installed yet."""
    try:
        root = _site_packages(ENV) / "acados" / "install"
        if (root / "lib" / "libhpipm.so").is_file():
            return
    except BenchError:
        pass
    print(f"HPIPM anchor missing in {ENV}: running bench/setup_hpipm.sh", flush=True)
    subprocess.run(["bash", str(BENCH / "setup_hpipm.sh")], check=True,
                   env={**os.environ, "BENCH_ENV": str(ENV)})


def hpipm_targets(with_casadi: bool) -> dict:
    """name -> {include: [...], libdir, label} of every HPIPM build to benchmark."""
    root = _site_packages(ENV) / "acados" / "install"
    target = "unknown"
    tfile = root / "include" / "blasfeo" / "include" / "blasfeo_target.h"
    for line in tfile.read_text().splitlines():
        if line.startswith("#define TARGET_") and "NEED_FEATURE" not in line:
            target = line.split()[1][len("TARGET_"):]
            break
    out = {"acados": {"include": [root / "include" / "blasfeo" / "include", root / "include" / "hpipm" / "include"],
                      "libdir": root / "lib",
                      "label": f"comma-deps-acados wheel, BLASFEO {target}"}}
    if with_casadi:
        try:
            import casadi  # the project's CasADi; bench/.env is never on sys.path
            cdir = Path(casadi.__file__).resolve().parent
            if (cdir / "libhpipm.so").is_file() and (cdir / "include" / "hpipm_d_ocp_qp_ipm.h").is_file():
                ctarget = "unknown"
                for line in (cdir / "include" / "blasfeo_target.h").read_text().splitlines():
                    if line.startswith("#define TARGET_"):
                        ctarget = line.split()[1][len("TARGET_"):]
                        break
                out["casadi"] = {"include": [cdir / "include"], "libdir": cdir,
                                 "label": f"casadi {casadi.__version__} wheel, BLASFEO {ctarget}"}
        except ImportError:
            pass
    return out


def _rename(text: str) -> str:
    """The code generator's textual prefix renaming (dopus_ -> qpbn_), so a second copy of our
    solver, compiled with other flags, links into the same program (and the benchmark's own
    qp_bench_dopus files become qp_bench_qpbn)."""
    return rename_placeholder(text.replace("bench_dopus", "bench_qpbn"), "qpbn")


def _compile(cmd: list) -> None:
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise BenchError("compiling the benchmark harness failed:\n" + " ".join(cmd) + "\n" + r.stderr[-4000:])


def build_harness(hp_name: str, hp: dict, sizes: dict | None, cflags: str, alt_cflags: str | None = None) -> Path:
    """Compile qp_bench_main against one HPIPM build and (sizes given) our solver; with
    alt_cflags also a renamed copy of our solver compiled with those flags."""
    BUILD.mkdir(parents=True, exist_ok=True)
    tag = hp_name
    srcs = [BENCH / s for s in HARNESS_SOURCES]
    incs = [BENCH] + list(hp["include"])
    defs, objs = [], []
    deps = list(srcs) + list(BENCH.glob("qp_bench_*.h"))
    if sizes is not None:
        tag += "_N{N}_nx{nx}_nu{nu}_ng{ng}_nr{nr}_ne{ne}".format(**sizes)
        sdir = BUILD / f"sizes_{tag}"
        sdir.mkdir(exist_ok=True)
        sizes_h = render_sizes_header("dopus", sizes, header="sizes of the benchmark build")
        (sdir / "dopus_sizes.h").write_text(sizes_h)
        incs = [sdir] + incs + [RUNTIME]
        ours = [BENCH / "qp_bench_dopus.c", RUNTIME / "dopus_qp.c", RUNTIME / "dopus_linalg.c"]
        srcs += ours
        deps += ours + [BENCH / "qp_bench_dopus.h", *RUNTIME.glob("dopus_*.h")]
        defs.append("-DQPB_WITH_DOPUS")
        if alt_cflags:
            tag += "_alt"
            adir = BUILD / f"alt_{tag}"
            adir.mkdir(exist_ok=True)
            (adir / "qpbn_sizes.h").write_text(_rename(sizes_h))
            for src in (BENCH / "qp_bench_dopus.c", BENCH / "qp_bench_dopus.h", RUNTIME / "dopus_qp.c",
                        RUNTIME / "dopus_linalg.c", *sorted(RUNTIME.glob("dopus_*.h"))):
                (adir / _rename(src.name)).write_text(_rename(src.read_text()))
            for c in ("qp_bench_qpbn.c", "qpbn_qp.c", "qpbn_linalg.c"):
                obj = adir / (c[:-2] + ".o")
                _compile(["cc", *CASADI_CFLAGS[:1], *shlex.split(alt_cflags), f"-I{adir}", f"-I{BENCH}", "-c",
                          str(adir / c), "-o", str(obj)])
                objs.append(obj)
            incs.append(adir)
            defs.append("-DQPB_WITH_DOPUS_ALT")
    exe = BUILD / f"qp_bench_{tag}"
    stamp = exe.with_suffix(".flags")
    flags_key = f"{cflags} | {alt_cflags} | {hp['libdir']}"
    if exe.is_file() and stamp.is_file() and stamp.read_text() == flags_key and not objs and \
            all(exe.stat().st_mtime >= d.stat().st_mtime for d in deps if d.exists()):
        return exe
    _compile(["cc", *STRICT_CFLAGS[:3], *shlex.split(cflags), *defs,
              *[f"-I{i}" for i in incs], *map(str, srcs), *map(str, objs), "-o", str(exe),
              f"-L{hp['libdir']}", "-Wl,--disable-new-dtags", f"-Wl,-rpath,{hp['libdir']}",
              "-lhpipm", "-lblasfeo", "-lm"])
    stamp.write_text(flags_key)
    return exe


# ---------------------------------------------------------------------------- QP files
def write_qps(path: Path, qps: list) -> None:
    """Binary layout of bench/qp_bench_qp.h; QPs in the dopus_codegen.reference.qp dict format."""
    chunks = [struct.pack("<d", float(len(qps)))]

    def put(a):
        chunks.append(np.asarray(a, dtype="<f8").ravel(order="F").tobytes())

    for q in qps:
        N, nx, nu, ng, nr, ne = (int(q[k]) for k in ("N", "nx", "nu", "ng", "nr", "ne"))
        put([N, nx, nu, ng, nr, ne])
        put(q["x0"])
        for k in range(N):
            put(q["H"][k]); put(q["g"][k]); put(q["Phi"][k]); put(q["b"][k])
            put(np.reshape(q["C"][k], (ng, nx + nu))); put(np.reshape(q["lg"][k], ng))
            put(np.reshape(q["ug"][k], ng)); put(q["lbw"][k]); put(q["ubw"][k])
        put(q["HN"]); put(q["gN"]); put(q["lbxN"]); put(q["ubxN"])
        put(np.reshape(q["R"], (nr, nx))); put(np.reshape(q["lr"], nr)); put(np.reshape(q["ur"], nr))
        put(np.reshape(q["Req"], (ne, nx))); put(np.reshape(q["req"], ne))
    path.write_bytes(b"".join(chunks))


def random_qp(N: int, rng: np.random.Generator) -> dict:
    """A feasible random QP with the robot's sizes: stable-ish dynamics, positive definite
    stage blocks, |du| <= 1 on the 3 controls (some active), 2 terminal equality rows that a
    trajectory strictly inside the bounds satisfies."""
    nx, nu, nw = NX, NU, NX + NU
    from scipy.linalg import expm
    H = np.empty((N, nw, nw)); Phi = np.empty((N, nx, nw)); b = np.empty((N, nx)); g = np.empty((N, nw))
    for k in range(N):
        K = rng.standard_normal((nx, nx))
        Phi[k, :, :nx] = expm(0.1 * (K - K.T) / 2) * 0.99 + 0.02 * rng.standard_normal((nx, nx))
        Phi[k, :, nx:] = 0.1 * rng.standard_normal((nx, nu))
        Mh = rng.standard_normal((nw, nw))
        H[k] = Mh @ Mh.T / nw + 0.1 * np.eye(nw)
        g[k] = rng.standard_normal(nw)
        b[k] = 0.01 * rng.standard_normal(nx)
    x0 = 0.5 * rng.standard_normal(nx)
    # a feasible trajectory strictly inside the bounds fixes the terminal right-hand side
    x = x0.copy()
    for k in range(N):
        u = rng.uniform(-0.5, 0.5, nu)
        x = Phi[k] @ np.concatenate([x, u]) + b[k]
    Req = rng.standard_normal((NE, nx))
    MN = rng.standard_normal((nx, nx))
    lbw = np.full((N, nw), -np.inf); ubw = np.full((N, nw), np.inf)
    lbw[:, nx:] = -1.0; ubw[:, nx:] = 1.0
    return {"N": N, "nx": nx, "nu": nu, "ng": 0, "nr": 0, "ne": NE, "H": H, "g": g, "Phi": Phi, "b": b,
            "x0": x0, "HN": MN @ MN.T / nx + 0.1 * np.eye(nx), "gN": rng.standard_normal(nx),
            "lbw": lbw, "ubw": ubw, "lbxN": np.full(nx, -np.inf), "ubxN": np.full(nx, np.inf),
            "C": np.zeros((N, 0, nw)), "lg": np.zeros((N, 0)), "ug": np.zeros((N, 0)),
            "R": np.zeros((0, nx)), "lr": np.zeros(0), "ur": np.zeros(0), "Req": Req, "req": Req @ x}


def _record_qps(ref, xhat, iters, tag, out):
    """Append the QP of each of ``iters`` iterations of ``ref`` at ``xhat`` to ``out``."""
    for it in range(iters):
        out.append((f"{tag}_{it}", ref.qp_of_current(xhat)))
        ref.feedback(xhat)
        ref.prepare()


def robot_arm_qps(gn_iters: int, exact_iters: int, log=print) -> list:
    """(tag, qp) along the two convergence runs of the robot arm, full RTI, fixed xhat_0."""
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.problem.ocp import load_ocp
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.reference.dopus import ReferenceDopus

    disc = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    full = disc.N - 1
    out = []
    t0 = time.perf_counter()
    # cold start, Gauss-Newton (docs/design.md section 8: the exact Hessian diverges from there)
    ref = ReferenceDopus(disc, M=full, mode="fixed", hessian="gauss-newton")
    xhat = np.asarray(disc.x0, float)
    ref.init(xhat)
    _record_qps(ref, xhat, gn_iters, "cold_gn", out)
    log(f"  robot arm: {gn_iters} cold Gauss-Newton QPs, KKT {ref.kkt(xhat)['kkt']:.1e} "
        f"({time.perf_counter() - t0:.1f} s)")
    # warm start: converged at xhat_0, then the disturbed initial state, exact Hessian
    t0 = time.perf_counter()
    guess, _ = solve_ocp(disc, xhat)
    xdist = disc.disturbance(xhat) if disc.disturbance is not None else xhat
    ref = ReferenceDopus(disc, M=full, mode="fixed", hessian="exact")
    ref.init(xhat, guess)
    _record_qps(ref, xdist, exact_iters, "warm_exact", out)
    log(f"  robot arm: {exact_iters} warm exact-Hessian QPs, KKT {ref.kkt(xdist)['kkt']:.1e} "
        f"({time.perf_counter() - t0:.1f} s)")
    return out


# ---------------------------------------------------------------------------- running
def run_harness(exe: Path, qps: list, solvers: list, reps: int, warmup: int, tol: float,
                iter_max: int, workdir: Path, budget: float, min_reps: int, extra: tuple = ()) -> tuple:
    """Run one harness; returns (per-QP result dicts, primal solutions [qp, solver, n])."""
    workdir.mkdir(parents=True, exist_ok=True)
    qfile, sfile = workdir / "qps.bin", workdir / "sol.bin"
    write_qps(qfile, qps)
    cmd = [str(exe), str(qfile), "--reps", str(reps), "--warmup", str(warmup), "--tol", repr(tol),
           "--iter-max", str(iter_max), "--sol", str(sfile), "--budget", repr(budget), "--min-reps", str(min_reps),
           *extra]
    for s in solvers:
        if s["kind"] == "hpipm":
            cmd += ["--hpipm", s["name"], str(s["mode"]), str(s["eq_mask"]), repr(s["eq_scale"]), str(s["ric_alg"])]
        elif s["kind"] == "dopus_alt":
            cmd += ["--dopus-alt", s["name"]]
        elif s["kind"] == "dopus_warm":
            # the QP indices where a new sequence (run) starts: there the warm chain starts cold
            resets = [i for i, q in enumerate(qps) if i == 0 or q.get("_run") != qps[i - 1].get("_run")]
            cmd += ["--dopus-warm", s["name"], ",".join(map(str, resets))]
        else:
            cmd += ["--dopus", s["name"]]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise BenchError(f"{exe.name} failed ({r.returncode}): {r.stderr.strip()}")
    rows = [json.loads(line) for line in r.stdout.splitlines() if line.strip()]
    n = qps[0]["N"] * (qps[0]["nx"] + qps[0]["nu"]) + qps[0]["nx"]
    sol = np.fromfile(sfile, dtype="<f8").reshape(len(qps), len(solvers), n)
    return rows, sol, cmd


TIE_QP = 0.05  # paired per-QP ratios this close to the best count as a tie for HPIPM's best mode


def paired_ratios(exe: Path, qps: list, configs: list, eq_scale: float, reps: int, warmup: int, tol: float,
                  iter_max: int, workdir: Path, rounds: int, log=print, alt: bool = False) -> dict:
    """Ours against each HPIPM configuration in ``configs`` as paired ratios: one harness run
    per round with only these solvers, the order of the solvers rotating from one repetition
    to the next (``--rotate``), every repetition's time kept (``--times``). Per QP and
    configuration the paired ratio is the median over the repetitions of ours' time over the
    configuration's time in the same round of solves (a few hundred microseconds apart, so a
    change of the machine's load or clock hits both); per IPM iteration it is that times the
    configuration's iterations over ours (both deterministic). A round's figure is the median
    over the QPs; the spread is given over the QPs (quartiles) and over the rounds (least and
    largest round). ``best`` is the configuration that is fastest against ours per QP (the
    largest median ours/QP): HPIPM's best converging mode, chosen on paired ratios so that two
    modes of nearly equal time do not swap on the noise of their separate medians. With ``alt``
    (the harness has the copy of our solver built with --alt-cflags) that copy runs in the same
    rounds and gets the same ratios under the keys ``alt/...``; ``best`` is chosen on ours. Needs
    at least one round and one repetition (the command line's 0 skips the comparison)."""
    if rounds < 1 or reps < 1:
        raise ValueError(f"paired_ratios: rounds and reps must be at least 1, got {rounds} and {reps}")
    solvers = [{"kind": "dopus", "name": "ours"}]
    mine = {"ours": "ours"}
    if alt:
        solvers.append({"kind": "dopus_alt", "name": "ours_alt"})
        mine["alt"] = "ours_alt"
    for name in configs:
        cfg = HPIPM_CONFIGS[name]
        solvers.append({"kind": "hpipm", "name": name, "mode": HPIPM_MODES[cfg["mode"]], "eq_mask": cfg["eq_mask"],
                        "eq_scale": eq_scale if cfg["eq_scale"] else 0.0, "ric_alg": cfg["ric_alg"]})
    per_round = []  # [round][(who, config)] -> (per-QP ratio per QP, per-QP ratio per iteration)
    pooled = {(w, c): [[] for _ in qps] for w in mine for c in configs}  # every repetition's ratio per QP
    iters = {}
    cmd = None
    for rnd in range(rounds):
        rows, _, cmd = run_harness(exe, qps, solvers, reps, warmup, tol, iter_max, workdir, 1e30, reps,
                                   extra=("--rotate", "--times"))
        this = {}
        for w, c in pooled:
            qp_r, it_r = [], []
            for i, row in enumerate(rows):
                o, h = row["solvers"][mine[w]], row["solvers"][c]
                ratios = np.asarray(o["t_reps"], float) / np.asarray(h["t_reps"], float)
                pooled[(w, c)][i].extend(ratios.tolist())
                iters[(w, c, i)] = (h["iterations"], o["iterations"])
                r = float(np.median(ratios))
                qp_r.append(r)
                it_r.append(r * h["iterations"] / o["iterations"] if o["iterations"] and h["iterations"] else np.nan)
            this[(w, c)] = (qp_r, it_r)
        per_round.append(this)
    out = {"configs": {}, "rounds": rounds, "reps": reps, "command": " ".join(shlex.quote(str(c)) for c in cmd)}
    for w, c in pooled:
        qp_all = [float(np.median(v)) for v in pooled[(w, c)]]
        it_all = [qp_all[i] * iters[(w, c, i)][0] / iters[(w, c, i)][1]
                  if iters[(w, c, i)][1] and iters[(w, c, i)][0] else np.nan for i in range(len(qps))]
        rq = [float(np.nanmedian(per_round[k][(w, c)][0])) for k in range(rounds)]
        ri = [float(np.nanmedian(per_round[k][(w, c)][1])) for k in range(rounds)]
        out["configs"].setdefault(c, {}).update({
            f"{w}/qp": float(np.nanmedian(qp_all)), f"{w}/qp_q25_q75": [float(np.nanpercentile(qp_all, 25)),
                                                                         float(np.nanpercentile(qp_all, 75))],
            f"{w}/iter": float(np.nanmedian(it_all)), f"{w}/iter_q25_q75": [float(np.nanpercentile(it_all, 25)),
                                                                             float(np.nanpercentile(it_all, 75))],
            f"{w}/qp_rounds": rq, f"{w}/iter_rounds": ri,
            "iterations_median": float(np.median([iters[(w, c, i)][0] for i in range(len(qps))])),
            f"{w}_iterations_median": float(np.median([iters[(w, c, i)][1] for i in range(len(qps))])),
            f"per_qp_{w}/qp": qp_all, f"per_qp_{w}/iter": it_all})
    out["best"] = max(configs, key=lambda c: out["configs"][c]["ours/qp"]) if configs else None
    if out["best"] is not None:
        # configurations within TIE_QP of the best per QP are as fast as it on this machine (the
        # choice among them is noise): the conservative per-iteration figure is the largest
        best_qp = out["configs"][out["best"]]["ours/qp"]
        tied = [c for c in configs if out["configs"][c]["ours/qp"] >= best_qp * (1.0 - TIE_QP)]
        out["tied"] = tied
        out["tied_worst_iter"] = max(tied, key=lambda c: out["configs"][c]["ours/iter"])
    return out


def print_paired(title: str, paired: dict, log=print) -> None:
    log(f"\n{title}: paired ratios (ours / HPIPM in the same round of solves, order rotating), "
        f"{paired['rounds']} rounds of {paired['reps']} repetitions; median over the QPs [quartiles over the QPs] "
        f"(least .. largest round)")
    log(f"{'config':24s} {'iters':>5s} {'ours':>5s} {'ours/QP':>24s} {'ours/iter':>24s}")
    for c, r in paired["configs"].items():
        q, it = r["ours/qp_q25_q75"], r["ours/iter_q25_q75"]
        log(f"{c:24s} {r['iterations_median']:5.1f} {r['ours_iterations_median']:5.1f} "
            f"{r['ours/qp']:5.3f} [{q[0]:.3f}, {q[1]:.3f}] ({min(r['ours/qp_rounds']):.3f}..{max(r['ours/qp_rounds']):.3f}) "
            f"{r['ours/iter']:5.3f} [{it[0]:.3f}, {it[1]:.3f}] ({min(r['ours/iter_rounds']):.3f}.."
            f"{max(r['ours/iter_rounds']):.3f})" + ("   <- best converging" if c == paired["best"] else
                                                     "   <- tied with it per QP" if c in paired.get("tied", ())
                                                     else ""))
        if "alt/qp" in r:
            q, it = r["alt/qp_q25_q75"], r["alt/iter_q25_q75"]
            log(f"{'  ours_alt':24s} {r['iterations_median']:5.1f} {r['alt_iterations_median']:5.1f} "
                f"{r['alt/qp']:5.3f} [{q[0]:.3f}, {q[1]:.3f}] ({min(r['alt/qp_rounds']):.3f}..{max(r['alt/qp_rounds']):.3f}) "
                f"{r['alt/iter']:5.3f} [{it[0]:.3f}, {it[1]:.3f}] ({min(r['alt/iter_rounds']):.3f}.."
                f"{max(r['alt/iter_rounds']):.3f})")


def primal_of(sol: dict) -> np.ndarray:
    N = sol["u"].shape[0]
    return np.concatenate([np.concatenate([sol["x"][k], sol["u"][k]]) for k in range(N)] + [sol["x"][N]])


def reference_primals(qps: list, log=print) -> list:
    """Primal solutions of the independent reference (IPOPT + active-set polish)."""
    from dopus_codegen.reference.qp import solve_qp_reference
    out = []
    for q in qps:
        try:
            out.append(primal_of(solve_qp_reference(q)))
        except Exception as exc:  # a reference failure is reported, not fatal
            log(f"  reference QP solver failed: {exc}")
            out.append(None)
    return out


def objective(q: dict, dw: np.ndarray) -> float:
    N, nw = q["N"], q["nx"] + q["nu"]
    J = 0.0
    for k in range(N):
        w = dw[k * nw:(k + 1) * nw]
        J += 0.5 * w @ q["H"][k] @ w + q["g"][k] @ w
    xN = dw[N * nw:]
    return float(J + 0.5 * xN @ q["HN"] @ xN + q["gN"] @ xN)


def summarise(rows: list, sols: np.ndarray, refs: list, qps: list, names: list, tags: list) -> list:
    """Flatten the harness output; add each primal's distance to the reference (inf-norm),
    and its objective's relative distance to the reference objective."""
    out = []
    for i, row in enumerate(rows):
        entry = {"tag": tags[i], "N": row["N"], "solvers": {}}
        if refs[i] is not None:
            jref = objective(qps[i], refs[i])
            entry["reference"] = {"objective": jref, "primal_inf_norm": float(np.max(np.abs(refs[i])))}
        for j, name in enumerate(names):
            s = dict(row["solvers"][name])
            s["time_per_iter"] = s["t_median"] / s["iterations"] if s["iterations"] else None
            if s.get("factorizations"):
                # ours: per factorisation of the Riccati recursion (interior-point iterations,
                # inertia corrections, sweeps of an active-set start)
                s["time_per_factorization"] = s["t_median"] / s["factorizations"]
            s["err_vs_reference"] = None
            s["obj_rel_err_vs_reference"] = None
            if refs[i] is not None:
                s["err_vs_reference"] = float(np.max(np.abs(sols[i, j] - refs[i])))
                s["obj_rel_err_vs_reference"] = abs(objective(qps[i], sols[i, j]) - jref) / max(1.0, abs(jref))
            entry["solvers"][name] = s
        out.append(entry)
    return out


def add_hpipm_best(entries: list, tol: float) -> None:
    """Per QP, the fastest configuration of the anchor build that converged to the tolerance by
    its own measure (status 0 and every HPIPM residual <= tol): the strictest comparison."""
    for e in entries:
        best = None
        for n, s in e["solvers"].items():
            if not n.startswith("hpipm") or n.startswith("hpipm_casadi") or s["status"] != 0:
                continue
            if max(s.get("residuals") or [np.inf]) > tol:
                continue
            if best is None or s["t_median"] < e["solvers"][best]["t_median"]:
                best = n
        if best is not None:
            e["solvers"]["hpipm_best"] = dict(e["solvers"][best], config=best)
        else:
            e["solvers"]["hpipm_best"] = {"status": -1, "iterations": 0, "t_median": None, "time_per_iter": None,
                                          "err_vs_reference": None, "config": None}


def converging_modes(entries: list, tol: float) -> dict:
    """Per HPIPM configuration of the anchor build: on how many of the QPs it converged to
    the tolerance by its own measure (status 0, every residual <= tol), its median time per
    QP and per IPM iteration, and ours against it (medians of the per-QP ratios, per QP and
    per iteration). ``best`` is the fastest configuration (median per QP) that converged on
    every QP: HPIPM's best converging mode."""
    out = {}
    for n in entries[0]["solvers"]:
        if not n.startswith("hpipm") or n.startswith("hpipm_casadi") or n == "hpipm_best":
            continue
        ok = [e for e in entries if e["solvers"][n]["status"] == 0
              and max(e["solvers"][n].get("residuals") or [np.inf]) <= tol]
        row = {"converged": len(ok), "of": len(entries),
               "t_median": med([e["solvers"][n]["t_median"] for e in entries]),
               "time_per_iter_median": med([e["solvers"][n]["time_per_iter"] for e in entries]),
               "iterations_median": med([e["solvers"][n]["iterations"] for e in entries])}
        for ours in ("ours", "ours_alt", "ours_warm"):
            if ours in entries[0]["solvers"]:
                row[f"{ours}/qp"] = med([e["solvers"][ours]["t_median"] / e["solvers"][n]["t_median"]
                                         for e in entries if e["solvers"][n]["t_median"]])
                row[f"{ours}/iter"] = med([e["solvers"][ours]["time_per_iter"] / e["solvers"][n]["time_per_iter"]
                                           for e in entries if e["solvers"][n]["time_per_iter"]
                                           and e["solvers"][ours]["time_per_iter"]])
                # ours per factorisation against HPIPM per IPM iteration (one factorisation each)
                row[f"{ours}/fact"] = med([e["solvers"][ours]["time_per_factorization"]
                                           / e["solvers"][n]["time_per_iter"] for e in entries
                                           if e["solvers"][n]["time_per_iter"]
                                           and e["solvers"][ours].get("time_per_factorization")])
        out[n] = row
    full = [n for n, r in out.items() if r["converged"] == r["of"]]
    return {"configs": out, "best": min(full, key=lambda n: out[n]["t_median"]) if full else None}


def print_modes(title: str, modes: dict, log=print) -> None:
    log(f"\n{title}: HPIPM configurations, converged QPs (own residuals <= tol), medians, ours against each "
        f"(medians of the per-QP ratios)")
    log(f"{'config':24s} {'conv':>6s} {'us/QP':>8s} {'iters':>6s} {'us/iter':>8s} {'ours/QP':>8s} {'ours/it':>8s} "
        f"{'ours/fac':>8s} {'alt/QP':>7s} {'alt/it':>7s} {'warm/QP':>7s} {'warm/fac':>8s}")
    for n, r in modes["configs"].items():
        f = lambda v, w=8, d=2: f"{v:{w}.{d}f}" if v is not None else " " * (w - 1) + "-"  # noqa: E731
        log(f"{n:24s} {r['converged']:3d}/{r['of']:<2d} {f(1e6 * r['t_median'] if r['t_median'] else None, 8, 1)} "
            f"{f(r['iterations_median'], 6, 1)} "
            f"{f(1e6 * r['time_per_iter_median'] if r['time_per_iter_median'] else None, 8, 1)} "
            f"{f(r.get('ours/qp'))} {f(r.get('ours/iter'))} {f(r.get('ours/fact'))} {f(r.get('ours_alt/qp'), 7)} "
            f"{f(r.get('ours_alt/iter'), 7)} {f(r.get('ours_warm/qp'), 7)} {f(r.get('ours_warm/fact'))}"
            + ("   <- best converging" if n == modes["best"] else ""))


def med(vals):
    vals = [v for v in vals if v is not None and np.isfinite(v)]
    return float(np.median(vals)) if vals else None


def fmt_us(t):
    return "       -" if t is None else f"{1e6 * t:8.1f}"


def table(title: str, groups: dict, names: list, ratios: list, log=print, shown=None) -> dict:
    """Print one table (rows: groups of QPs; columns: the solvers in ``shown``, all if None,
    then the ratios); return the medians per group for every solver.

    ``ratios``: (numerator, denominator) solver names; a ratio is the median over the QPs of
    the per-QP ratios (per QP and per IPM iteration)."""
    ratios = [(a, b) for a, b in ratios if a in names and b in names]
    cols = [n for n in names if shown is None or n in shown]
    log(f"\n{title}")
    log(f"{'QPs':<18}{'#':>4}" + "".join(f" | {n:>25}" for n in cols)
        + "".join(f" | {a + '/' + b:>21}" for a, b in ratios))
    log(f"{'':<18}{'':>4}" + "".join(f" | {'us/QP iters us/iter ok':>25}" for _ in cols)
        + "".join(f" | {'QP   iter':>21}" for _ in ratios))
    summary = {}
    for gname, entries in groups.items():
        if not entries:
            continue
        line = f"{gname:<18}{len(entries):>4}"
        gs = {}
        for n in names:
            t = med([e["solvers"][n]["t_median"] for e in entries])
            it = med([e["solvers"][n]["iterations"] for e in entries])
            tpi = med([e["solvers"][n]["time_per_iter"] for e in entries])
            ok = sum(1 for e in entries if e["solvers"][n]["status"] == 0)
            errs = [e["solvers"][n]["err_vs_reference"] for e in entries
                    if e["solvers"][n]["err_vs_reference"] is not None]
            oerrs = [e["solvers"][n]["obj_rel_err_vs_reference"] for e in entries
                     if e["solvers"][n].get("obj_rel_err_vs_reference") is not None]
            fac = med([e["solvers"][n].get("factorizations") for e in entries])
            gs[n] = {"t_median": t, "iterations_median": it, "time_per_iter_median": tpi, "factorizations_median": fac,
                     "converged": ok, "count": len(entries),
                     "err_vs_reference_max": max(errs) if errs else None,
                     "obj_rel_err_vs_reference_max": max(oerrs) if oerrs else None,
                     "statuses": sorted({e["solvers"][n]["status"] for e in entries})}
            if n in cols:
                line += f" | {fmt_us(t)} {it if it is not None else 0:5.1f} {fmt_us(tpi)} {ok:>2}"
        for a, b in ratios:
            r_qp = med([e["solvers"][a]["t_median"] / e["solvers"][b]["t_median"] for e in entries
                        if e["solvers"][b]["t_median"]])
            r_it = med([e["solvers"][a]["time_per_iter"] / e["solvers"][b]["time_per_iter"]
                        for e in entries if e["solvers"][a]["iterations"] and e["solvers"][b]["time_per_iter"]])
            gs[f"ratio_{a}_over_{b}"] = {"per_qp": r_qp, "per_iter": r_it}
            line += (f" | {r_qp if r_qp is not None else float('nan'):10.2f} "
                     f"{r_it if r_it is not None else float('nan'):10.2f}")
        log(line)
        summary[gname] = gs
    return summary


def markdown_table(summary: dict, cols: list, ratios: list) -> str:
    """The summary of one QP set as a markdown table (what bench/README.md shows). Cell:
    time per QP / iterations / time per iteration in microseconds (converged/count)."""
    first = next(iter(summary.values()))
    ratios = [(a, b) for a, b in ratios if f"ratio_{a}_over_{b}" in first]
    out = ["| QPs | " + " | ".join(cols) + " | " + " | ".join(f"{a}/{b} QP (iter)" for a, b in ratios) + " |",
           "|---|" + "---|" * (len(cols) + len(ratios))]
    for g, gs in summary.items():
        cells = []
        for c in cols:
            v = gs.get(c)
            cells.append("-" if v is None or v["t_median"] is None else
                         f"{1e6 * v['t_median']:.0f} / {v['iterations_median']:.1f} / "
                         f"{1e6 * v['time_per_iter_median']:.1f} ({v['converged']}/{v['count']})")
        for a, b in ratios:
            v = gs.get(f"ratio_{a}_over_{b}")
            cells.append("-" if v is None or v["per_qp"] is None else
                         f"**{v['per_qp']:.2f}** ({v['per_iter']:.2f})" if v["per_iter"] is not None
                         else f"**{v['per_qp']:.2f}**")
        out.append(f"| {g} (#{gs['ours']['count'] if 'ours' in gs else '?'}) | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tol", default="1e-8", help="tolerance of every solver (default %(default)s); several "
                    "comma-separated (e.g. 1e-6,1e-8,1e-10) run the whole bench once per tolerance, one JSON each "
                    "(qp_bench_tol<tol>.json) and a summary of the robot-arm QPs per tolerance")
    ap.add_argument("--reps", type=int, default=200, help="timed repetitions per QP and solver")
    ap.add_argument("--warmup", type=int, default=20, help="untimed repetitions first")
    ap.add_argument("--budget", type=float, default=1.5,
                    help="seconds of timed runs per QP (all solvers of one harness), reps reduced to fit")
    ap.add_argument("--min-reps", type=int, default=30, help="fewest timed repetitions despite the budget")
    ap.add_argument("--iter-max", type=int, default=100)
    ap.add_argument("--random-per-n", type=int, default=5, help="random QPs per horizon length")
    ap.add_argument("--gn-iters", type=int, default=20, help="cold Gauss-Newton robot-arm QPs")
    ap.add_argument("--exact-iters", type=int, default=6, help="warm exact-Hessian robot-arm QPs")
    ap.add_argument("--eq-scale", type=float, default=1e3,
                    help="hpipm_scaled: terminal equality rows divided by eq_scale * max|row| (default %(default)g)")
    ap.add_argument("--cflags", default=DEFAULT_OPT, help="C flags of the harness and our solver "
                    "(default %(default)s, the generated Makefile's OPT)")
    ap.add_argument("--alt-cflags", default="-O3 -march=native",
                    help="flags of a second, renamed copy of our solver in the same process (column "
                         "ours_alt); '' to skip (default %(default)s)")
    ap.add_argument("--no-casadi-hpipm", action="store_true", help="skip the casadi wheel's HPIPM column")
    ap.add_argument("--no-robot", action="store_true", help="random QPs only")
    ap.add_argument("--no-random", action="store_true", help="robot-arm QPs only")
    ap.add_argument("--no-ours", action="store_true", help="HPIPM only (our solver not built)")
    ap.add_argument("--no-reference", action="store_true", help="skip the reference QP solves")
    ap.add_argument("--markdown", type=Path, default=None, help="also write the tables as markdown to this file")
    ap.add_argument("--wide", action="store_true", help="print every column (the JSON always has all)")
    ap.add_argument("--quick", action="store_true", help="smoke run: few repetitions and QPs")
    ap.add_argument("--paired-reps", type=int, default=200,
                    help="robot arm: repetitions per round of the paired comparison of ours against every "
                         "HPIPM configuration that converged on all QPs (0 skips it; default %(default)s)")
    ap.add_argument("--paired-rounds", type=int, default=3,
                    help="robot arm: separate harness runs of the paired comparison (0 skips it; default "
                         "%(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=RESULTS / "qp_bench.json")
    args = ap.parse_args(argv)
    try:
        tols = [float(t) for t in str(args.tol).split(",")]
    except ValueError:
        ap.error(f"--tol: expected numbers, got {args.tol!r}")
    for opt in ("paired_reps", "paired_rounds"):
        if getattr(args, opt) < 0:
            ap.error(f"--{opt.replace('_', '-')}: expected 0 or more, got {getattr(args, opt)}")
    if len(tols) > 1:
        return _several_tolerances(argv, tols, args.json)
    args.tol = tols[0]
    if args.quick:
        args.reps, args.warmup, args.random_per_n, args.gn_iters, args.exact_iters = 10, 2, 2, 4, 3
        args.min_reps = min(args.min_reps, args.reps)
    log = lambda *a: print(*a, flush=True)

    ensure_bench_env()
    with_ours = not args.no_ours
    if with_ours and not (RUNTIME / "dopus_qp.c").is_file():
        log("runtime_c/dopus_qp.c not found: HPIPM only")
        with_ours = False
    targets = hpipm_targets(not args.no_casadi_hpipm)
    log(f"HPIPM anchor: {targets['acados']['label']} ({targets['acados']['libdir']})")
    if "casadi" in targets:
        log(f"second HPIPM: {targets['casadi']['label']} (not the anchor)")
    log(f"tolerance {args.tol:g}, {args.reps} repetitions (+{args.warmup} warm-up, budget {args.budget:g} s "
        f"per QP), ours built with '{args.cflags}'" + (f", ours_alt with '{args.alt_cflags}'" if args.alt_cflags else ""))

    def solvers_for(robot: bool, hp_name: str):
        sv = []
        if with_ours and hp_name == "acados":
            sv.append({"kind": "dopus", "name": "ours"})
            if robot:
                # ours warm-started along each run as in the closed loop (the previous QP's
                # multipliers, the active-set start)
                sv.append({"kind": "dopus_warm", "name": "ours_warm"})
            if args.alt_cflags:
                sv.append({"kind": "dopus_alt", "name": "ours_alt"})
        for name, cfg in HPIPM_CONFIGS.items():
            if hp_name != "acados":
                if name not in ("hpipm", "hpipm_scaled"):
                    continue
                name = name.replace("hpipm", "hpipm_casadi")
            if cfg.get("robot_only") and not robot:
                continue
            sv.append({"kind": "hpipm", "name": name, "mode": HPIPM_MODES[cfg["mode"]], "eq_mask": cfg["eq_mask"],
                       "eq_scale": args.eq_scale if cfg["eq_scale"] else 0.0, "ric_alg": cfg["ric_alg"]})
        return sv

    last_run = {}  # the anchor's harness and QPs of the last set (the paired comparison reruns them)

    def bench_set(label: str, tagged: list, robot: bool) -> tuple:
        """Run one family of QPs (same sizes within each N) through every harness."""
        by_n = {}
        for tag, q in tagged:
            by_n.setdefault(int(q["N"]), []).append((tag, q))
        entries, cmds = [], []
        last_run.clear()
        for N, items in sorted(by_n.items()):
            tags = [t for t, _ in items]
            # the run a QP belongs to (its tag without the iteration): the warm chain's sequences
            qps = [dict(q, _run=t.rsplit("_", 1)[0]) for t, q in items]
            refs = [None] * len(qps) if args.no_reference else reference_primals(qps, log)
            sizes = {k: int(qps[0][k]) for k in ("N", "nx", "nu", "ng", "nr", "ne")}
            merged, prims = None, {}
            for hp_name, hp in targets.items():
                sv = solvers_for(robot, hp_name)
                exe = build_harness(hp_name, hp, sizes if any(s["kind"] == "dopus" for s in sv) else None,
                                    args.cflags, args.alt_cflags if hp_name == "acados" else None)
                rows, sols, cmd = run_harness(exe, qps, sv, args.reps, args.warmup, args.tol, args.iter_max,
                                              BUILD / f"run_{label}_{hp_name}_N{N}", args.budget, args.min_reps)
                if hp_name == "acados":
                    last_run.update(exe=exe, qps=qps, workdir=BUILD / f"paired_{label}_N{N}")
                cmds.append(" ".join(shlex.quote(c) for c in cmd))
                part = summarise(rows, sols, refs, qps, [s["name"] for s in sv], tags)
                prims.update({s["name"]: sols[:, j] for j, s in enumerate(sv)})
                if merged is None:
                    merged = part
                else:
                    for m, p in zip(merged, part):
                        m["solvers"].update(p["solvers"])
            if "ours" in prims:  # agreement among the solvers, independent of the reference
                for i, m in enumerate(merged):
                    for n, s in m["solvers"].items():
                        s["dist_to_ours"] = float(np.max(np.abs(prims[n][i] - prims["ours"][i])))
            entries += merged
        add_hpipm_best(entries, args.tol)
        return entries, cmds

    report = {"config": {"tol": args.tol, "reps": args.reps, "warmup": args.warmup, "iter_max": args.iter_max,
                         "budget": args.budget, "min_reps": args.min_reps,
                         "hpipm_configs": HPIPM_CONFIGS, "eq_scale": args.eq_scale, "cflags": args.cflags,
                         "alt_cflags": args.alt_cflags,
                         "hpipm": {k: {"label": v["label"], "libdir": str(v["libdir"])} for k, v in targets.items()},
                         "machine": platform.processor() or platform.machine(),
                         "cpu": _cpu_name(), "seed": args.seed, "git_head": _git_head(),
                         "sources_sha1": {f: _sha1(RUNTIME / f) for f in ("dopus_qp.c", "dopus_qp.h",
                                                                          "dopus_linalg.c")}},
              "notes": NOTES}
    shown = None if args.wide else {"ours", "ours_alt", "hpipm", "hpipm_eqmask", "hpipm_robust", "hpipm_classic",
                                    "hpipm_scaled", "hpipm_casadi", "hpipm_best"}

    # random QPs
    rng = np.random.default_rng(args.seed)
    ns_run = () if args.no_random else RANDOM_NS
    tagged = [(f"random_N{N}_{i}", random_qp(N, rng)) for N in ns_run for i in range(args.random_per_n)]
    if tagged:
        log(f"\nrandom QPs: {len(tagged)} ({args.random_per_n} per N)")
        entries, cmds = bench_set("random", tagged, robot=False)
        names = list(entries[0]["solvers"])
        groups = {f"random N={N}": [e for e in entries if e["N"] == N] for N in RANDOM_NS}
        report["random"] = {"qps": entries, "summary": table(
            "Random QPs (nx=5, nu=3, 3 control bounds, 2 terminal equality rows), medians", groups, names,
            RANDOM_RATIOS, log, shown), "commands": cmds}
        # growth of the time per IPM iteration with N: least-squares fit t = c N^p over the
        # per-N medians (p = 1 is the linear cost of the Riccati recursion)
        fits = {}
        for name in names:
            ns, ts = [], []
            for N in RANDOM_NS:
                v = report["random"]["summary"].get(f"random N={N}", {}).get(name, {}).get("time_per_iter_median")
                if v is not None and np.isfinite(v) and v > 0:
                    ns.append(N)
                    ts.append(v)
            if len(ns) >= 2:
                fits[name] = float(np.polyfit(np.log(ns), np.log(ts), 1)[0])
        report["random"]["time_per_iter_exponent"] = fits
        log("time per IPM iteration ~ N^p over N = " + ", ".join(map(str, RANDOM_NS)) + ": "
            + ", ".join(f"{k} p = {v:.2f}" for k, v in fits.items()))

    if not args.no_robot:
        log("\nrobot-arm QPs (Python reference, full RTI, fixed xhat_0)")
        tagged = robot_arm_qps(args.gn_iters, args.exact_iters, log)
        entries, cmds = bench_set("robot", tagged, robot=True)
        names = list(entries[0]["solvers"])
        groups = {"robot cold GN": [e for e in entries if e["tag"].startswith("cold_gn")],
                  "robot warm exact": [e for e in entries if e["tag"].startswith("warm_exact")],
                  "robot all": entries}
        report["robot_arm"] = {"modes": converging_modes(entries, args.tol), "qps": entries, "summary": table(
            "Robot-arm QPs (N=40), medians; hpipm/hpipm_eqmask: equality as stated; hpipm_scaled: rows rescaled "
            "by hand", groups, names, ROBOT_RATIOS, log, shown), "commands": cmds}
        st = {n: sorted({HPIPM_STATUS.get(e['solvers'][n]['status'], str(e['solvers'][n]['status']))
                         if n.startswith("hpipm") else DOPUS_STATUS.get(e['solvers'][n]['status'], '?')
                         for e in entries}) for n in names if n != "hpipm_best"}
        log("statuses on the robot-arm QPs: " + "; ".join(f"{n}: {', '.join(v)}" for n, v in st.items()))
        print_modes(f"robot-arm QPs, tolerance {args.tol:g}", report["robot_arm"]["modes"], log)
        modes = report["robot_arm"]["modes"]["configs"]
        full = [n for n, r in modes.items() if r["converged"] == r["of"] and n in HPIPM_CONFIGS]
        if with_ours and args.paired_reps > 0 and args.paired_rounds > 0 and full and last_run:
            paired = paired_ratios(last_run["exe"], last_run["qps"], full, args.eq_scale, args.paired_reps,
                                   args.warmup, args.tol, args.iter_max, last_run["workdir"], args.paired_rounds, log,
                                   alt=bool(args.alt_cflags))
            report["robot_arm"]["paired"] = paired
            print_paired(f"robot-arm QPs, tolerance {args.tol:g}", paired, log)

    if args.markdown is not None:
        md = [f"tolerance {args.tol:g}, commit {report['config']['git_head']}, "
              f"sources {report['config']['sources_sha1']}\n"]
        if "robot_arm" in report:
            names = [n for n in ("ours", "ours_alt", "hpipm", "hpipm_classic", "hpipm_scaled",
                                 "hpipm_casadi_scaled", "hpipm_best") if n in report["robot_arm"]["summary"]["robot all"]]
            md += ["\nRobot-arm QPs\n\n", markdown_table(report["robot_arm"]["summary"], names, ROBOT_RATIOS)]
        if "random" in report:
            first = next(iter(report["random"]["summary"].values()))
            names = [n for n in ("ours", "ours_alt", "hpipm", "hpipm_robust", "hpipm_casadi", "hpipm_best")
                     if n in first]
            md += ["\nRandom QPs\n\n", markdown_table(report["random"]["summary"], names, RANDOM_RATIOS)]
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text("".join(md))
        log(f"wrote {args.markdown}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(report, indent=1, default=_json_default))
    log(f"\nwrote {args.json}")
    return 0


def _several_tolerances(argv, tols, json_path: Path) -> int:
    """The bench once per tolerance (same arguments otherwise), then the robot-arm summary:
    per tolerance HPIPM's best converging configuration and ours against it."""
    argv = list(sys.argv[1:] if argv is None else argv)
    rest, skip = [], False
    for a in argv:
        if skip:
            skip = False
            continue
        if a == "--tol" or a == "--json":
            skip = True
            continue
        if a.startswith("--tol=") or a.startswith("--json="):
            continue
        rest.append(a)
    summary = {}
    for tol in tols:
        out = json_path.with_name(f"{json_path.stem}_tol{tol:g}{json_path.suffix}")
        rc = main([*rest, "--tol", repr(tol), "--json", str(out)])
        if rc != 0:
            return rc
        rep = json.loads(out.read_text())
        if "robot_arm" in rep:
            summary[f"{tol:g}"] = dict(rep["robot_arm"]["modes"], paired=rep["robot_arm"].get("paired"))
    print("\nrobot-arm QPs per tolerance: HPIPM's best converging configuration and ours against it "
          "(medians of the per-QP ratios)")
    for tol, m in summary.items():
        b = m["best"]
        if b is None:
            print(f"  tol {tol}: no HPIPM configuration converged on every QP")
            continue
        r = m["configs"][b]
        print(f"  tol {tol}: {b} ({r['converged']}/{r['of']}, {1e6 * r['t_median']:.1f} us/QP, "
              f"{r['iterations_median']:g} iterations): ours/QP {r.get('ours/qp', float('nan')):.2f}, "
              f"ours/iter {r.get('ours/iter', float('nan')):.2f}, ours per factorisation / its per iteration "
              f"{r.get('ours/fact') if r.get('ours/fact') is not None else float('nan'):.2f}; ours_warm (active-set "
              f"start from the previous QP) per QP {r.get('ours_warm/qp') or float('nan'):.2f}, per factorisation "
              f"{r.get('ours_warm/fact') or float('nan'):.2f}; ours_alt {r.get('ours_alt/qp', float('nan')):.2f} / "
              f"{r.get('ours_alt/iter', float('nan')):.2f}")
    print("\nrobot-arm QPs per tolerance, paired ratios (ours / HPIPM in the same round of solves): HPIPM's best "
          "converging configuration, median over the QPs [quartiles over the QPs] (least .. largest round)")
    for tol, m in summary.items():
        p = m.get("paired")
        if not p or p["best"] is None:
            print(f"  tol {tol}: no paired comparison")
            continue
        r = p["configs"][p["best"]]
        q, it = r["ours/qp_q25_q75"], r["ours/iter_q25_q75"]
        tw = p["tied_worst_iter"]
        rt = p["configs"][tw]
        print(f"  tol {tol}: {p['best']} ({r['iterations_median']:g} against {r['ours_iterations_median']:g} "
              f"iterations): ours/QP {r['ours/qp']:.3f} [{q[0]:.3f}, {q[1]:.3f}] ({min(r['ours/qp_rounds']):.3f}.."
              f"{max(r['ours/qp_rounds']):.3f}), ours/iter {r['ours/iter']:.3f} [{it[0]:.3f}, {it[1]:.3f}] "
              f"({min(r['ours/iter_rounds']):.3f}..{max(r['ours/iter_rounds']):.3f}); tied per QP (within "
              f"{100 * TIE_QP:g} %): {', '.join(p['tied'])}, largest ours/iter among them {rt['ours/iter']:.3f} "
              f"({tw}, ours/QP {rt['ours/qp']:.3f})")
        if "alt/qp" in r:
            q, it = r["alt/qp_q25_q75"], r["alt/iter_q25_q75"]
            print(f"           ours_alt against {p['best']}: alt/QP {r['alt/qp']:.3f} [{q[0]:.3f}, {q[1]:.3f}], "
                  f"alt/iter {r['alt/iter']:.3f} [{it[0]:.3f}, {it[1]:.3f}] ({min(r['alt/iter_rounds']):.3f}.."
                  f"{max(r['alt/iter_rounds']):.3f}); against {tw}: alt/iter {rt['alt/iter']:.3f}")
    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json.dumps({"tolerances": summary}, indent=1, default=_json_default))
    return 0


NOTES = ("Times are medians over repetitions of the solve call alone (the data already in each solver's "
         "structures; t_set_median is the copy-in, HPIPM's conversion to BLASFEO panels, ours the vector copies). "
         "Repetitions are interleaved solver by solver in one process after warm-up. Every solver gets the same "
         "tolerance value; each measures it its own way (HPIPM: inf-norms of its residuals; ours: scaled KKT "
         "residuals), so the residuals and err_vs_reference (max |dw - dw_ref|, reference: IPOPT + active-set "
         "polish of dopus_codegen.reference.qp) are recorded per QP. HPIPM status: 0 success, 1 max_iter, 2 min_step, "
         "3 nan, 4 inconsistent equality. Ours: 0 solved, 1 max_iter, 2 primal infeasible, 3 dual infeasible, "
         "4 numerical, 5 invalid input.")


def _git_head() -> str:
    r = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    return r.stdout.strip()


def _sha1(path: Path):
    import hashlib
    return hashlib.sha1(path.read_bytes()).hexdigest()[:12] if path.is_file() else None


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(type(o).__name__)


if __name__ == "__main__":
    try:
        sys.exit(main())
    except BenchError as exc:
        print(f"qp_bench: {exc}", file=sys.stderr)
        sys.exit(1)
