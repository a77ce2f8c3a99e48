"""What keeps a stuck run of the robot arm's fault loop stuck (bench/issue23/measurements.md
section 44): the run of bench/stuck_sweep.py (M = 1, the initial first joint angle moved by
eps, SETTLE exact measurements, K with joint velocities (30, -30)) is followed to instant J
after the fault; from that state (the solver's whole state copied, the plant's state) the
loop goes on for 60 instants once per variant: unchanged, the Levenberg-Marquardt term fixed
(0, the held value, 10 and 100 times it), more stages re-linearised (M = 5, the full RTI, the
full RTI for 10 instants), the Gauss-Newton Hessian. Per variant: the KKT proxy after 0, 5, 10,
20, 40 and 59 instants, the term at the end, the control error against IPOPT's optimum at the
same state (every 10th instant, share of the control range) and the tip's distance from the
circle at the end. The stuck state is that of a runtime without the held-lm flat test of
docs/algorithm.md section 9 (main ae64192, where section 44's table was measured): with it
the run (6e-6, 12) is flagged at instant 45 after the fault and is no longer stuck at 100.

    .venv/bin/python bench/stuck_mechanism.py [EPS K J]      (default: 6e-6 12 100)
"""
from __future__ import annotations

import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from harness.faults import KINDS, SETTLE, Handle, instant, model_plant, tip_deviation  # noqa: E402

from dopus_codegen import build_functions, load_ocp  # noqa: E402
from dopus_codegen.reference.offline import solve_ocp  # noqa: E402
from dopus_codegen.studies import loops  # noqa: E402


def main(eps=6e-6, K=12, J=100, n=60):
    arm = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess, _ = solve_ocp(arm, arm.x0)
    plant = model_plant(arm)
    span = np.asarray(arm.ubu, float) - np.asarray(arm.lbu, float)
    h = Handle(arm, guess, 1)
    x = np.asarray(arm.x0, float).copy()
    x[0] += eps
    h.init(x)
    for i in range(SETTLE + K + J):
        xm = KINDS["velocity 30"](x, None) if SETTLE <= i < SETTLE + K else x.copy()
        x, _, _ = instant(h, plant, x, xm)
    x_at, lm = x.copy(), h.s.lm
    print(f"eps {eps:g}, K {K}, instant {J} after the fault: proxy {h.s.kkt_proxy:.4f}, lm {lm:.4g} "
          f"({lm / h.s.lm_scale:.2e} h), KKT {h.s.kkt()}")

    def variant(name, setup, switch=None):
        s = Handle(arm, guess, 1).s
        s.copy_state_from(h.s)
        setup(s)
        x, prox, errs = x_at.copy(), [], []
        for t in range(n):
            if switch and t == switch[0]:
                switch[1](s)
            fb = loops.feedback(s, x)
            if t % 10 == 9:
                ref, info = solve_ocp(arm, x, guess=s.guess())
                errs.append(float(np.max(np.abs(fb.u0 - ref.u[0]) / span)) if info["success"] else float("nan"))
            x = plant(x, fb.u0)
            loops.prepare(s)
            prox.append(s.kkt_proxy)
        print(f"| {name} | " + " / ".join(f"{prox[t]:.3f}" for t in (0, 5, 10, 20, 40, n - 1))
              + f" | {s.lm:.3g} | " + " ".join(f"{100 * e:.0f}" for e in errs)
              + f" | {1e3 * tip_deviation(x)[0]:.1f} |", flush=True)

    print("| variant | proxy after 0 / 5 / 10 / 20 / 40 / 59 instants | lm at the end "
          "| control error [% of range], every 10th | tip off [mm] |")
    print("|---|---|---|---|---|")
    variant("unchanged", lambda s: None)
    variant("lm fixed 0", lambda s: s.set_levenberg_marquardt(0.0))
    variant("lm fixed at the held value", lambda s: s.set_levenberg_marquardt(lm))
    variant("lm fixed 10 x", lambda s: s.set_levenberg_marquardt(10 * lm))
    variant("lm fixed 100 x", lambda s: s.set_levenberg_marquardt(100 * lm))
    variant("M = 5", lambda s: s.set_M(5))
    variant("full RTI", lambda s: s.set_M(arm.N - 1))
    variant("full RTI for 10, then M = 1", lambda s: s.set_M(arm.N - 1), switch=(10, lambda s: s.set_M(1)))
    variant("full RTI, lm fixed 0", lambda s: (s.set_M(arm.N - 1), s.set_levenberg_marquardt(0.0)))
    variant("Gauss-Newton", lambda s: s.set_hessian("gauss-newton"))
    variant("Gauss-Newton for 10, then exact", lambda s: s.set_hessian("gauss-newton"),
            switch=(10, lambda s: s.set_hessian("exact")))


if __name__ == "__main__":
    a = sys.argv[1:]
    main(*(float(a[0]), int(a[1]), int(a[2])) if a else ())
