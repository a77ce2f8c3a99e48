"""Stuck runs of the robot arm's fault loop over (eps, K): do they settle, get caught by the
flat stall test, or stay stuck unseen (bench/issue23/measurements.md sections 40 and 42)?

The runs of tests/test_faults.py's ``_stuck_run``: M = 1, the initial first joint angle moved
by eps, SETTLE (50) exact measurements, K with joint velocities (30, -30), AFTER (150) exact
ones (tests/harness/faults.py). Per run, over the last 50 instants: the KKT measure of the
iterate after each prepare (``CSolver.kkt()``, max of its four parts) and the proxy the health
tests use (``CSolver.kkt_proxy``, the stationarity and equality parts at the prepared point;
the flat test compares it with DOPUS_FLAT_KKT max(1, proxy at init)), median and min; the
control error of every 5th feedback against IPOPT's optimum at the same state started from the
loop's iterate (max over the controls of |u0 - u0_ipopt| / control range), median and max;
the tip deviation at the end; the health flags seen after the fault; failed instants after it;
the longest stretch after the fault with the proxy in the flat test's blind band [1, 5) and no
stall flag (its length, proxy, KKT measure and control error); the class (see classify); the
instants (after the fault; negative: before its end) at which the flat test with a lower
threshold would fire on the run's proxy series (offline, flat_fires).

    .venv/bin/python bench/stuck_sweep.py [--eps E1,E2,...] [--K K1,K2,...] [--out FILE]
    .venv/bin/python bench/stuck_sweep.py --table [JSON ...]

Defaults: the 30 eps of section 42's first sweep, K 10..13; --out bench/issue23/stuck_sweep.json
(rewritten after every run). Classes (given the K = 0 runs' KKT medians as the unfaulted
level): see classify.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from harness.faults import AFTER, KINDS, SETTLE, Handle, instant, model_plant, tip_deviation  # noqa: E402

from dopus_codegen import build_functions, load_ocp, vocabulary  # noqa: E402
from dopus_codegen.reference.offline import solve_ocp  # noqa: E402
from dopus_codegen.studies import loops  # noqa: E402

EPS = [0.0, 1e-9, -1e-9, 1e-8, -1e-8, 1e-7, -1e-7, 1e-6, -1e-6, 3e-9, -3e-9, 3e-8, -3e-8, 3e-7, -3e-7,
       2e-9, -2e-9, 5e-9, -5e-9, 2e-8, -2e-8, 5e-8, -5e-8, 2e-7, -2e-7, 5e-7, -5e-7, 1e-10, -1e-10, 1e-5]
KS = [10, 11, 12, 13]
TAIL = 50       # the last instants measured
EVERY = 5       # IPOPT on every 5th instant after the fault (the last one included)
# the flat test's constants, read from runtime_c/dopus_health.h (DOPUS_FLAT_KKT, _PREPARES, _DROP)
FLAT_KKT, FLAT_PREPARES, FLAT_DROP = (vocabulary.constants()[k] for k in ("FLAT_KKT", "FLAT_PREPARES", "FLAT_DROP"))
LOWER = (1.0, 1.5, 2.0, 3.0, 4.0, 5.0)    # flat thresholds tried offline on the proxy series (5: the check)
BAND_FLOOR = 1.0    # the blind band's floor: above the unfaulted run's proxy (largest 0.55, last 50)
SETTLED_KKT = 1.0   # a settled tail: KKT median at most this (unfaulted run: 0.515)
UERR_STUCK = 0.15   # a stuck control: median error above this share of the control range


def stretches(mask):
    """(start, length) of the runs of True in mask."""
    out, start = [], None
    for j, v in enumerate(list(mask) + [False]):
        if v and start is None:
            start = j
        elif not v and start is not None:
            out.append((start, j - start))
            start = None
    return out


def flat_fires(proxies, recovering, threshold):
    """The instants at which the flat stall test with DOPUS_FLAT_KKT replaced by ``threshold``
    would fire on this series of proxies (runtime_c/dopus_health.c, the reference max(1, proxy
    at init) = 1 here; offline: the loop is the one of the unchanged runtime). The counter is
    reset in the prepares of a recovery phase, as the runtime's (read as M_used = N - 1)."""
    fires, n_flat, ref = [], 0, 0.0
    for j, (p, rec) in enumerate(zip(proxies, recovering)):
        if rec:
            n_flat = 0
            continue
        flat = p > threshold
        if not flat or n_flat == 0 or not p > FLAT_DROP * ref:
            ref, n_flat = p, 0
        n_flat = n_flat + 1 if flat else 0
        if n_flat >= FLAT_PREPARES:
            fires.append(j)
            n_flat = 0
    return fires


def run(arm, plant, guess, span, eps, K):
    h = Handle(arm, guess, 1)
    x = np.asarray(arm.x0, float).copy()
    x[0] += eps
    h.init(x)
    proxy_init = h.s.kkt_proxy
    n = SETTLE + K + AFTER
    flags, failed, kkts, proxies, errs, stalled = set(), 0, [], [], {}, []
    flag_instants, series, full = {}, [], []
    for i in range(n):
        xm = KINDS["velocity 30"](x, None) if SETTLE <= i < SETTLE + K else x.copy()
        j = i - SETTLE - K
        if j >= 0 and (n - 1 - i) % EVERY == 0:
            fb = loops.feedback(h, xm)
            ref, info = solve_ocp(arm, x, guess=h.s.guess())
            errs[j] = float(np.max(np.abs(fb.u0 - ref.u[0]) / span)) if info["success"] else float("nan")
            x = plant(x, fb.u0)
            st2, _ = loops.prepare(h)
            st = fb.status or st2
        else:
            x, _, st = instant(h, plant, x, xm)
        series.append(float(h.s.kkt_proxy))
        full.append(h.s.M_used >= arm.N - 1)
        if j >= 0:
            failed += st != 0
            for f in h.s.flags:
                flag_instants.setdefault(f, []).append(j)
            flags |= h.s.flags
            kkts.append(float(h.s.kkt()["kkt"]))
            proxies.append(float(h.s.kkt_proxy))
            stalled.append("stalled" in h.s.flags)
    threshold = FLAT_KKT * max(1.0, float(proxy_init))
    kt, pt = np.array(kkts[-TAIL:]), np.array(proxies[-TAIL:])
    et = [v for j, v in errs.items() if j >= AFTER - TAIL]
    # the longest stretch after the fault with the proxy in the flat test's blind band
    # [BAND_FLOOR, threshold) and no stall flag
    p = np.array(proxies)
    band = [(s, m) for s, m in stretches((p >= BAND_FLOOR) & (p < threshold) & ~np.array(stalled))]
    s0, m0 = max(band, key=lambda t: t[1]) if band else (0, 0)
    eb = [v for j, v in errs.items() if s0 <= j < s0 + m0]
    blind = {"start": s0, "length": m0}
    if m0:
        blind.update(proxy_median=float(np.median(p[s0:s0 + m0])), proxy_min=float(p[s0:s0 + m0].min()),
                     proxy_max=float(p[s0:s0 + m0].max()), kkt_median=float(np.median(kkts[s0:s0 + m0])),
                     kkt_min=float(np.min(kkts[s0:s0 + m0])), kkt_max=float(np.max(kkts[s0:s0 + m0])),
                     uerr_median=float(np.nanmedian(eb)) if eb else None,
                     uerr_max=float(np.nanmax(eb)) if eb else None, samples=len(eb))
    return {"eps": eps, "K": K, "proxy_init": float(proxy_init), "flat_threshold": threshold,
            "kkt_median": float(np.median(kt)), "kkt_min": float(kt.min()), "kkt_max": float(kt.max()),
            "proxy_median": float(np.median(pt)), "proxy_min": float(pt.min()), "proxy_max": float(pt.max()),
            "uerr_median": float(np.nanmedian(et)), "uerr_max": float(np.nanmax(et)),
            "ipopt_failed": int(np.sum(np.isnan(list(errs.values())))),
            "dev_end": float(tip_deviation(x)[0]), "flags": sorted(flags),
            "flag_first_last": {f: [v[0], v[-1]] for f, v in flag_instants.items()},
            "failed_after": int(failed), "recoveries": int(h.s.recoveries), "blind": blind,
            "lower_fires": {str(t): [j - SETTLE - K for j in flat_fires(series, full, t)] for t in LOWER},
            "class": classify(float(np.median(kt)), float(np.nanmedian(et)), "stalled" in flags, blind)}


def classify(kkt_median, uerr_median, stalled, blind):
    """missed at the end: the last 50 instants' KKT median above SETTLED_KKT and their median
    control error above UERR_STUCK, no stall flag; missed, then free: such a stretch of at least
    FLAT_PREPARES instants earlier in the window (proxy in the blind band, median control error
    above UERR_STUCK) with no stall flag in it; caught: the stall flag seen after the fault;
    settled: otherwise."""
    if kkt_median > SETTLED_KKT and uerr_median > UERR_STUCK and not stalled:
        return "missed at the end"
    if blind["length"] >= FLAT_PREPARES and (blind.get("uerr_median") or 0.0) > UERR_STUCK:
        return "missed, then free"
    if stalled:
        return "caught"
    return "settled"


def table(paths):
    """The markdown table and the counts per class of the runs in the JSON files."""
    rows = [r for p in paths for r in json.loads(pathlib.Path(p).read_text())["runs"]]
    print("| eps | K | KKT med / min (last 50) | proxy med / min | u err med / max | dev end [mm] "
          "| failed | flags | blind band: instants, proxy med (min-max), KKT med, u err med | class |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in sorted(rows, key=lambda r: (r["K"], r["eps"])):
        b = r["blind"]
        bb = (f"{b['length']} from {b['start']}: {b['proxy_median']:.2f} ({b['proxy_min']:.2f}-{b['proxy_max']:.2f}), "
              f"{b['kkt_median']:.2f}, {100 * (b['uerr_median'] or 0):.0f} %") if b["length"] else "0"
        fl = ", ".join(f for f in r["flags"] if f in ("stalled", "diverged", "fallback", "recovered"))
        print(f"| {r['eps']:.1e} | {r['K']} | {r['kkt_median']:.2f} / {r['kkt_min']:.2f} | "
              f"{r['proxy_median']:.2f} / {r['proxy_min']:.3f} | {100 * r['uerr_median']:.1f} / {100 * r['uerr_max']:.0f} % "
              f"| {1e3 * r['dev_end']:.1f} | {r['failed_after']} | {fl} | {bb} | {r['class']} |")
    counts = {}
    for r in rows:
        counts.setdefault(r["K"], {}).setdefault(r["class"], 0)
        counts[r["K"]][r["class"]] += 1
    print()
    for K in sorted(counts):
        print(f"K = {K}: " + ", ".join(f"{c} {n}" for c, n in sorted(counts[K].items())))
    print()
    print("| flat threshold | runs it fires in (first time: after the fault / before its end) | K = 0 runs "
          "| missed runs it fires in within their blind stretch (median prepares into it) "
          "| other runs in which it fires first where 5 does not |")
    print("|---|---|---|---|---|")
    nm = sum(r["class"].startswith("missed") for r in rows)
    for t in LOWER:
        after = before = k0 = missed = other = 0
        into = []
        for r in rows:
            f, f5 = r["lower_fires"][str(t)][:1], r["lower_fires"]["5.0"][:1]  # the first fire changes the loop
            if not f:
                continue
            after += f[0] >= 0
            before += f[0] < 0
            k0 += r["K"] == 0
            b = r["blind"]
            if r["class"].startswith("missed"):
                if b["start"] <= f[0] < b["start"] + b["length"]:
                    missed += 1
                    into.append(f[0] - b["start"] + 1)
            elif r["K"] > 0 and f != f5:
                other += 1
        print(f"| {t} | {after} / {before} of {len(rows)} | {k0} | {missed} of {nm} "
              f"({np.median(into) if into else '-'}) | {other} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--eps", default=None, help="comma-separated shifts of the first joint angle")
    ap.add_argument("--K", default=None, help="comma-separated fault lengths (0: unfaulted)")
    ap.add_argument("--out", default=str(pathlib.Path("bench") / "issue23" / "stuck_sweep.json"),
                    help="JSON output (relative to the repository root unless absolute)")
    ap.add_argument("--append", action="store_true", help="add to the runs already in --out")
    ap.add_argument("--table", nargs="*", default=None, metavar="JSON",
                    help="print the markdown table and counts of these JSON files instead of running")
    a = ap.parse_args()
    if a.table is not None:
        table(a.table or [ROOT / "bench" / "issue23" / "stuck_sweep.json"])
        return
    eps = EPS if a.eps is None else [float(v) for v in a.eps.split(",")]
    ks = KS if a.K is None else [int(v) for v in a.K.split(",")]
    out = pathlib.Path(a.out)
    out = out if out.is_absolute() else ROOT / out
    arm = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess, _ = solve_ocp(arm, arm.x0)
    plant = model_plant(arm)
    span = np.asarray(arm.ubu, float) - np.asarray(arm.lbu, float)
    rows = json.loads(out.read_text())["runs"] if a.append and out.exists() else []
    print(f"{'eps':>8} {'K':>3} {'kkt med':>8} {'kkt min':>8} {'prx med':>8} {'prx min':>8} "
          f"{'uerr med':>8} {'uerr max':>8} {'dev end':>8} {'failed':>6} {'bl':>3} {'class':>17} flags")
    for K in ks:
        for e in eps:
            t = time.time()
            r = run(arm, plant, guess, span, e, K)
            rows.append(r)
            print(f"{e:8.0e} {K:3d} {r['kkt_median']:8.2e} {r['kkt_min']:8.2e} {r['proxy_median']:8.2e} "
                  f"{r['proxy_min']:8.2e} {r['uerr_median']:8.3f} {r['uerr_max']:8.3f} {r['dev_end']:8.4f} "
                  f"{r['failed_after']:6d} {r['blind']['length']:3d} {r['class']:>17} {','.join(r['flags'])} ({time.time() - t:.0f} s)", flush=True)
            out.write_text(json.dumps({"command": "bench/stuck_sweep.py", "settle": SETTLE, "after": AFTER,
                                       "tail": TAIL, "every": EVERY, "runs": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
