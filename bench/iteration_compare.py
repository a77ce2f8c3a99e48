"""One DOPUS iteration of two generated robot-arm solvers, side by side in one process.

One command compares this tree against an older commit, each built at its own default
flags:

    .venv/bin/python bench/iteration_compare.py --old-commit c2a9b53 --repeat 3

`--old-commit REV` exports that commit's `generated/robot_arm` (`git archive`) into
bench/results/iteration_compare/<commit>/robot_arm and builds it with the folder's own
Makefile and its defaults (`make build/lib<name>.so`, with OPT, CC, PIC, EXTRA_CFLAGS
removed from the environment): what `dopus-gen build` of that commit did too. For c2a9b53
that is -O2, the runtime files with `-std=c99 -Wall -Wextra -Werror -pedantic` and the
CasADi file with `-std=c99 -Wall`. Nothing of the old folder is changed and nothing is
relaxed. Today's `dopus-gen build` (and the Python handle, which builds through it) cannot
build such a folder: since f44b878 it compiles the CasADi file with the strict flags too
(the generator now marks CasADi's unused parameters), and c2a9b53's CasADi file has 44
unused parameters (`iw`, `w`, `mem` of its 11 function bodies, `mem` of the 11 `*_release`),
errors under -Wextra -Werror (-Wunused-parameter). Today's handle cannot load it either:
c2a9b53 declares `robot_arm_get_dims(int *dims)` (ten ints), the handle
asks for the `robot_arm_dims` struct of 65d976d (the same ten ints in memory) and for
functions c2a9b53 does not have (`get_u0` on a failed feedback, `set_lm_auto`,
`set_qp_warm_start`, ...). So an `--old-commit` folder is loaded as built, through its own
cdef (:class:`FolderHandle`: `defaults`, `set_M`, `init`, `feedback`, `prepare`,
`get_timings`, `get_qp_iterations`, `get_u`: c2a9b53's folder and this tree's both have them),
with every other setting at that folder's generated defaults (c2a9b53: exact Hessian, no
regularisation, lm 1e-4 from its OCP file).

The new side is, unless `--new FOLDER` is given, a copy of this tree's `generated/robot_arm`
in bench/results/iteration_compare/new, built by this tree's `dopus-gen build` at the
default flags (-O3) and loaded with `CSolver` (its own generated settings; lm: the OCP
file's, now the automatic term). Folders built beforehand (`dopus-gen build FOLDER [--opt
...]`; the folder keeps the flags it was built with) compare with `--old FOLDER [--new
FOLDER]`, both loaded with `CSolver`, e.g. a commit after 65d976d:

    git worktree add --detach /tmp/old 7b77c20
    cp -r /tmp/old/generated/robot_arm /tmp/cmp_old && dopus-gen build /tmp/cmp_old
    .venv/bin/python bench/iteration_compare.py --old /tmp/cmp_old

Run: the receding-horizon closed loop on the discrete model (this tree's OCP file) from the
IPOPT solution, M = 1, exact Hessian, each solver's own Levenberg-Marquardt setting (as
`dopus-gen sil`), the OCP file's disturbance at the first and the middle iteration; every
solver runs its own loop, the instants interleaved (old, new, old, new, ...) so that load on
the machine hits both alike. Times are the C runtime's own phase timers. Reported: medians
per iteration of feedback (the QP and its bookkeeping), prepare and their sum, the ratio new
/ old (and the median of the per-instant ratios, the same instant of both loops paired), the
QP share (feedback / iteration) and the QP iterations per instant (failed instants count
there and as failures, not in the times), and the QP's factorisations per instant (median and
99th percentile) of a folder that counts them. Progress goes to stderr, the table to stdout,
everything with the build commands to --json (default
bench/results/iteration_compare/<old>.json). Never passes or fails on time.
"""
from __future__ import annotations

import argparse
import io
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PREPARE = ("shift", "gradients", "rho", "hessians", "regularization", "assembly")
WORKDIR = ROOT / "bench" / "results" / "iteration_compare"
FOLDER = "generated/robot_arm"
#: Environment variables a generated Makefile reads (`VAR ?= default`): removed so that
#: `make` builds at the folder's own defaults.
MAKE_OVERRIDES = ("OPT", "CC", "AR", "PIC", "EXTRA_CFLAGS", "CFLAGS", "MAKEFLAGS", "MFLAGS", "GNUMAKEFLAGS")
_DIMS = ("N", "nx", "nu", "nw", "np", "ng", "nr", "ne", "has_gn", "has_nominal")


class CompareError(RuntimeError):
    """A step of the preparation failed; the message says which and why."""


def say(msg: str) -> None:
    print(f"iteration_compare: {msg}", file=sys.stderr, flush=True)


def _git(*args: str, binary: bool = False):
    try:
        proc = subprocess.run(["git", "-C", str(ROOT), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              check=False)
    except FileNotFoundError:
        raise CompareError("git not found (--old-commit needs git)") from None
    if proc.returncode != 0:
        return None
    return proc.stdout if binary else proc.stdout.decode().strip()


def export_commit_folder(rev: str, workdir: Path) -> tuple:
    """``(commit, folder)``: ``generated/robot_arm`` of ``rev`` as committed, exported
    afresh into ``workdir/<commit[:12]>/robot_arm``."""
    sha = _git("rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")
    if not sha:
        raise CompareError(f"commit '{rev}' not found in the repository {ROOT}")
    if _git("cat-file", "-e", f"{sha}:{FOLDER}") is None:
        raise CompareError(f"commit {sha[:12]} ('{rev}') has no {FOLDER}")
    data = _git("archive", "--format=tar", sha, FOLDER, binary=True)
    if data is None:
        raise CompareError(f"git archive {sha[:12]} {FOLDER} failed")
    dest = workdir / sha[:12]
    shutil.rmtree(dest, ignore_errors=True)
    dest.mkdir(parents=True)
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        kw = {"filter": "data"} if hasattr(tarfile, "data_filter") else {}
        tar.extractall(dest, **kw)
    folder = dest / "robot_arm"
    (dest / FOLDER).rename(folder)
    shutil.rmtree(dest / "generated")
    say(f"exported {FOLDER} of {sha[:12]} ('{rev}') into {folder}")
    return sha, folder


def build_with_own_makefile(folder: Path) -> list:
    """``make build/lib<name>.so`` in ``folder`` at the Makefile's defaults; its compile and
    link commands (echoed to stderr)."""
    name = json.loads((folder / f"{folder.name}_meta.json").read_text())["name"]
    if not (folder / "Makefile").is_file():
        raise CompareError(f"{folder} has no Makefile")
    env = {k: v for k, v in os.environ.items() if k not in MAKE_OVERRIDES}
    target = f"build/lib{name}.so"
    say(f"building {folder} with its own Makefile: make {target}")
    try:
        proc = subprocess.run(["make", "-C", str(folder), target], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, check=False)
    except FileNotFoundError:
        raise CompareError("make not found (--old-commit builds the old folder with its own Makefile)") from None
    for line in proc.stdout.splitlines():
        print(f"  {line}", file=sys.stderr, flush=True)
    if proc.returncode != 0:
        raise CompareError(f"make {target} in {folder} failed (exit {proc.returncode}); its output is above")
    return [line for line in proc.stdout.splitlines() if re.match(r"^\S*(cc|gcc|clang)\s", line)]


def prepare_new(workdir: Path) -> Path:
    """This tree's ``generated/robot_arm`` copied into ``workdir/new`` and built by this
    tree's ``dopus-gen build`` at the default flags."""
    from dopus_codegen.codegen.build import build

    src = ROOT / FOLDER
    dest = workdir / "new" / "robot_arm"
    shutil.rmtree(dest.parent, ignore_errors=True)
    shutil.copytree(src, dest, ignore=shutil.ignore_patterns("build"))
    say(f"building this tree's {FOLDER} (copied into {dest}) with dopus-gen build at the default flags")
    build(dest, echo=say)
    return dest


class FolderHandle:
    """A built generated folder loaded as it is (never rebuilt), through its own cdef, with
    only calls that c2a9b53's folder and this tree's both have. Settings: the folder's
    generated defaults, then ``set_M``. The parts of the :class:`CSolver` interface the
    comparison uses: ``init``, ``feedback`` (raises DopusError on a non-zero status),
    ``prepare``, ``timings``, ``qp_iterations``, ``u``, ``sizeof``, ``lm``."""

    def __init__(self, disc, folder, M: int):
        import cffi

        from dopus_codegen.runtime.solver import DopusError

        self._error = DopusError
        folder = Path(folder)
        meta = json.loads(next(folder.glob("*_meta.json")).read_text())
        self.name = name = meta["name"]
        if meta.get("real", "double") != "double":
            raise CompareError(f"{folder} is generated in {meta['real']}; the comparison runs double")
        shared = folder / "build" / f"lib{name}.so"
        if not shared.is_file():
            raise CompareError(f"{shared} does not exist: build the folder first")
        cdef = (folder / meta["cdef"]).read_text()
        self._ffi = ffi = cffi.FFI()
        ffi.cdef(cdef)
        self._lib = ffi.dlopen(str(shared))
        if re.search(rf"\b{name}_dims\s*;", cdef):       # the struct of 65d976d and later
            buf = ffi.new(f"{name}_dims *")
            self._c("get_dims")(buf)
            dims = {f: int(getattr(buf, f)) for f in _DIMS}
        else:                                            # c2a9b53: get_dims(int *dims), ten ints
            buf = ffi.new("int[10]")
            self._c("get_dims")(buf)
            dims = dict(zip(_DIMS, (int(v) for v in buf)))
        self.N, self.nx, self.n_u = dims["N"], dims["nx"], dims["nu"]
        self.dims = dims
        want = tuple(int(v) for v in (disc.N, disc.nx, disc.nu, disc.np, disc.ng, disc.nr, disc.ne))
        have = tuple(dims[f] for f in ("N", "nx", "nu", "np", "ng", "nr", "ne"))
        if want != have or name != disc.name:
            raise CompareError(f"{folder} is '{name}' with sizes {have}, the OCP file's '{disc.name}' has {want}")
        from dopus_codegen import vocabulary

        self._phases = vocabulary.generated_enums(str(folder.resolve()), name)["dopus_phase"].names()
        self.sizeof = int(self._c("solver_sizeof")())
        self._mem = ffi.new("double[]", (self.sizeof + 7) // 8)
        self._s = ffi.cast(f"{name}_solver *", self._mem)
        # the settings struct and the info struct (setup, get_info) of the later runtimes;
        # the one-setting functions (defaults, set_M, get_timings, ...) of the earlier ones
        self._settings_api = re.search(rf"\b{name}_setup\s*\(", cdef) is not None
        if self._settings_api:
            st = ffi.new(f"{name}_settings *")
            self._c("settings_default")(st)
            st.M = int(min(M, self.N - 1))
            self._check(self._c("setup")(self._s, st), "setup")
        else:
            self._c("defaults")(self._s)
            self._check(self._c("set_M")(self._s, int(min(M, self.N - 1))), "set_M")

    def _c(self, fname: str):
        return getattr(self._lib, f"{self.name}_{fname}")

    def _check(self, status: int, what: str) -> None:
        if status != 0:
            text = self._ffi.string(self._c("status_string")(status)).decode()
            raise self._error(f"{self.name}: {what}: {text} (status {status})", int(status))

    def _ptr(self, a):
        return self._ffi.NULL if a is None else self._ffi.from_buffer("double[]", a)

    def init(self, xhat0, guess) -> None:
        fields = ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu")
        arrays = [getattr(guess, f, None) for f in fields]
        arrays = [None if a is None else np.ascontiguousarray(a, dtype=np.float64) for a in arrays]
        xh = np.ascontiguousarray(xhat0, dtype=np.float64)
        self._check(self._c("init")(self._s, self._ptr(xh), *[self._ptr(a) for a in arrays]), "init")

    def feedback(self, xhat0) -> np.ndarray:
        xh = np.ascontiguousarray(xhat0, dtype=np.float64)
        u0 = np.zeros(self.n_u)
        self._check(self._c("feedback")(self._s, self._ptr(xh), self._ptr(u0)), "feedback")
        return u0

    def prepare(self) -> None:
        self._check(self._c("prepare")(self._s), "prepare")

    def _info(self):
        info = self._ffi.new(f"{self.name}_info *")
        self._c("get_info")(self._s, info)
        return info

    @property
    def timings(self) -> dict:
        if self._settings_api:
            info = self._info()
            return {p: float(info.timings[i]) for i, p in enumerate(self._phases)}
        t = np.zeros(len(self._phases))
        self._c("get_timings")(self._s, self._ptr(t))
        return dict(zip(self._phases, (float(v) for v in t)))

    @property
    def qp_iterations(self) -> int:
        if self._settings_api:
            return int(self._info().qp_iterations)
        return int(self._c("get_qp_iterations")(self._s))

    @property
    def qp_factorizations(self):
        """The factorisations of the last feedback's QP (None: the folder does not count them)."""
        if self._settings_api:
            try:
                return int(self._info().qp_factorizations)
            except AttributeError:
                return None
        return None

    @property
    def u(self) -> np.ndarray:
        out = np.zeros((self.N, self.n_u))
        self._c("get_u")(self._s, self._ptr(out))
        return out

    @property
    def lm(self) -> float:
        if self._settings_api:
            return float(self._info().lm)
        return float(self._c("get_levenberg_marquardt")(self._s))


def _lm_text(s) -> str:
    return "auto" if getattr(s, "lm_auto", False) else f"{s.lm:g}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    old = ap.add_mutually_exclusive_group(required=True)
    old.add_argument("--old-commit", metavar="REV",
                     help="commit whose generated/robot_arm is the baseline: exported and built with its own "
                          "Makefile at its defaults")
    old.add_argument("--old", metavar="FOLDER", help="generated folder of the baseline, built by dopus-gen build")
    ap.add_argument("--new", metavar="FOLDER", default=None,
                    help="generated folder to compare, built by dopus-gen build (default: a copy of this "
                         "tree's generated/robot_arm built at the default flags)")
    ap.add_argument("--workdir", default=str(WORKDIR), help=f"where folders are prepared (default {WORKDIR})")
    ap.add_argument("--iters", type=int, default=200, help="closed-loop iterations per run (default 200)")
    ap.add_argument("--repeat", type=int, default=3, help="runs (default 3)")
    ap.add_argument("--M", type=int, default=1)
    ap.add_argument("--json", default=None, help="output JSON (default <workdir>/<old>.json)")
    args = ap.parse_args(argv)
    if args.iters < 1 or args.repeat < 1 or args.M < 0:
        ap.error("--iters and --repeat must be at least 1, --M at least 0")

    sys.path.insert(0, str(ROOT))
    from dopus_codegen import build_functions, load_ocp
    from dopus_codegen.codegen.build import recorded_opt
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.runtime.solver import CSolver, DopusError

    workdir = Path(args.workdir).resolve()
    config = {"git_head": _git("rev-parse", "HEAD"), "iters": args.iters, "repeat": args.repeat, "M": args.M}
    try:
        workdir.mkdir(parents=True, exist_ok=True)
        if args.old_commit:
            sha, old_dir = export_commit_folder(args.old_commit, workdir)
            commands = build_with_own_makefile(old_dir)
            config["old"] = {"commit": sha, "folder": str(old_dir), "build": "its own Makefile, default flags",
                             "commands": commands, "handle": "FolderHandle"}
            label = sha[:12]
        else:
            old_dir = Path(args.old)
            config["old"] = {"folder": str(old_dir), "opt": recorded_opt(old_dir), "handle": "CSolver"}
            label = old_dir.name
        new_dir = Path(args.new) if args.new else prepare_new(workdir)
        config["new"] = {"folder": str(new_dir), "handle": "CSolver"}

        say("solving the OCP with IPOPT for the initial guess")
        disc = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
        guess = solve_ocp(disc, disc.x0)[0]
        solvers = {}
        if args.old_commit:
            solvers["old"] = FolderHandle(disc, old_dir, args.M)
        else:
            solvers["old"] = CSolver(disc, lib_dir=old_dir, M=args.M, lm=None)
        solvers["new"] = CSolver(disc, lib_dir=new_dir, M=args.M, lm=None)
    except CompareError as exc:
        print(f"iteration_compare: error: {exc}", file=sys.stderr)
        return 2
    config["new"]["opt"] = recorded_opt(new_dir)
    for name, s in solvers.items():
        config[name]["lm"] = _lm_text(s)

    p0 = np.asarray(solvers["new"].p[0], dtype=float)
    rec = {name: {"feedback": [], "prepare": [], "qp_iters": [], "qp_fact": [], "failures": 0} for name in solvers}
    for run in range(args.repeat):
        say(f"run {run + 1} of {args.repeat}: {args.iters} instants each, interleaved")
        xs = {}
        for name, s in solvers.items():
            xs[name] = np.array(disc.x0, dtype=float)
            s.init(xs[name], guess)
        for it in range(args.iters):
            for name, s in solvers.items():
                x = xs[name]
                if it in (0, args.iters // 2):
                    x = np.array(disc.disturbance(x.copy()), dtype=float).reshape(-1)
                try:
                    u0 = s.feedback(x)
                    ok = True
                except DopusError:
                    rec[name]["failures"] += 1
                    u0, ok = s.u[0], False
                t_fb = s.timings["feedback"]
                rec[name]["qp_iters"].append(s.qp_iterations)
                rec[name]["qp_fact"].append(s.qp_factorizations)
                s.prepare()
                t = s.timings   # a failed instant stays in the lists as NaN: instants pair by index
                rec[name]["feedback"].append(t_fb if ok else np.nan)
                rec[name]["prepare"].append(sum(t[k] for k in PREPARE) if ok else np.nan)
                xs[name] = np.array(disc.stage_eval(x, u0, p0)[0], dtype=float).reshape(-1)
    out = {"config": config}
    for name, r in rec.items():
        fb, pr = np.array(r["feedback"]), np.array(r["prepare"])
        out[name] = {"feedback_us": float(np.nanmedian(fb) * 1e6), "prepare_us": float(np.nanmedian(pr) * 1e6),
                     "iteration_us": float(np.nanmedian(fb + pr) * 1e6),
                     "qp_share": float(np.nanmedian(fb / (fb + pr))),
                     "qp_iters_median": float(np.median(r["qp_iters"])),
                     "qp_iters_mean": float(np.mean(r["qp_iters"])), "failures": r["failures"],
                     "instants": len(r["qp_iters"]), "sizeof": solvers[name].sizeof}
        if all(f is not None for f in r["qp_fact"]):
            out[name]["qp_factorizations_median"] = float(np.median(r["qp_fact"]))
            out[name]["qp_factorizations_p99"] = float(np.percentile(r["qp_fact"], 99))
    out["ratio_new_old"] = out["new"]["iteration_us"] / out["old"]["iteration_us"]
    # the same instant of both loops ran back to back: the median of their ratios
    it_old, it_new = (np.array(rec[n]["feedback"]) + np.array(rec[n]["prepare"]) for n in ("old", "new"))
    out["ratio_new_old_paired"] = float(np.nanmedian(it_new / it_old))
    for name in ("old", "new"):
        o, c = out[name], config[name]
        what = c["commit"][:12] if "commit" in c else c["folder"]
        flags = "own Makefile defaults" if "commit" in c else (c.get("opt") or "?")
        print(f"{name} ({what}, {flags}, lm {c['lm']}): iteration {o['iteration_us']:.1f} us (feedback "
              f"{o['feedback_us']:.1f}, prepare {o['prepare_us']:.1f}), QP share {o['qp_share']:.0%}, QP iterations "
              f"median {o['qp_iters_median']:.0f} (mean {o['qp_iters_mean']:.1f}), failures {o['failures']} of "
              f"{o['instants']}, sizeof {o['sizeof']} B"
              + (f", QP factorisations median {o['qp_factorizations_median']:g}, 99th percentile "
                 f"{o['qp_factorizations_p99']:g}" if "qp_factorizations_median" in o else ""))
    print(f"new / old per iteration: {out['ratio_new_old']:.2f} (ratio of the medians), "
          f"{out['ratio_new_old_paired']:.2f} (median of the per-instant ratios)")
    path = Path(args.json) if args.json else workdir / f"{label}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1) + "\n")
    say(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
