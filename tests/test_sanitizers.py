"""The generated solvers under AddressSanitizer + UndefinedBehaviorSanitizer, and fuzzed.

For the robot arm and the unicycle, a copy of the checked-in generated folder is built twice
with its own Makefile (``make run``: static library + standalone main): plainly (cc -O2) and
with clang ``-fsanitize=address,undefined -fno-sanitize-recover=all`` (plus libFuzzer's
coverage instrumentation, so the same library serves the fuzz harness). Then:

- the standalone main and tests/fuzz/driver.c (fixed xhat0, Gauss-Newton projected from the
  cold guess, 25 closed-loop steps against the generated model with a push, and the C API's
  bad inputs) run in both builds: exit 0, no sanitizer report, the same statuses and every
  number equal to round-off (relative 1e-12; in practice the outputs are identical);
- the bad-input statuses of the driver equal the documented codes (runtime_c/dopus_solver.h);
- tests/fuzz/fuzz_solver.c (libFuzzer + ASan + UBSan) replays the checked-in corpus and
  every regression input, then fuzzes for a bounded time (``DOPUS_FUZZ_SECONDS``, default
  30 s per problem) from the corpus: it must end clean. Executions per second and the total
  are printed (``pytest -s``).
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess

import numpy as np
import pytest

import sanitizer_build as SB

PROBLEMS = {"robot_arm": "robot_disc", "unicycle": "second_disc"}
ROUND_OFF = 1e-12
FUZZ_SECONDS = int(os.environ.get("DOPUS_FUZZ_SECONDS", "30"))
OK, ERR_QP, NONFINITE_INPUT, INVALID, NOT_INIT, NOT_PREPARED, ALREADY_PREPARED = 0, 1, 2, 5, 6, 7, 10

# C API bad inputs of tests/fuzz/driver.c and their documented statuses; np == 0 problems
# accept any parameter array (arrays of size zero are not read).
BAD_INPUTS = {
    "feedback_before_init": NOT_INIT, "prepare_before_init": NOT_INIT, "kkt_before_init": NOT_INIT,
    "init_nan_xhat0": NONFINITE_INPUT, "init_inf_guess_x": NONFINITE_INPUT, "init_nominal": OK,
    "prepare_after_init": ALREADY_PREPARED, "feedback_null_xhat0": NONFINITE_INPUT,
    "feedback_nan_xhat0": NONFINITE_INPUT, "feedback_minus_inf_xhat0": NONFINITE_INPUT,
    "kkt_nan_xhat0": NONFINITE_INPUT, "feedback": OK, "feedback_twice": NOT_PREPARED, "prepare": OK,
    "prepare_twice": ALREADY_PREPARED, "set_M_negative": INVALID, "set_M_N": INVALID,
    "set_M_int_max": INVALID, "set_mode_2": INVALID, "set_hessian_minus_1": INVALID,
    "set_regularization_3": INVALID, "set_regularization_eps_0": INVALID,
    "set_regularization_eps_nan": INVALID, "set_cost_hessian_2": INVALID, "set_lm_negative": INVALID,
    "set_lm_inf": INVALID, "set_qp_tol_0": INVALID, "set_qp_tol_nan": INVALID,
    "set_qp_max_iter_0": INVALID, "set_qp_max_iter_int_min": INVALID,
    "set_parameters_node_minus_1": INVALID, "set_parameters_node_N_plus_1": INVALID,
    "set_parameters_nan": (NONFINITE_INPUT, OK), "set_parameters_null": (INVALID, OK),
    "set_parameters_node_nan": (NONFINITE_INPUT, OK), "init_nominal_again": OK,
    "status_string_unknown": OK, "final_feedback": OK,
}


@pytest.fixture(scope="module")
def clang(tmp_path_factory):
    cc = SB.find_clang(tmp_path_factory.mktemp("probe"))
    if cc is None:
        pytest.fail(SB.MISSING)
    return cc


@pytest.fixture(scope="module", params=sorted(PROBLEMS))
def built(request, clang, tmp_path_factory):
    """Both builds of one generated folder, the main's outputs, the drivers and the fuzzer."""
    name = request.param
    disc = request.getfixturevalue(PROBLEMS[name])
    tmp = tmp_path_factory.mktemp(f"san_{name}")
    src = SB.GENERATED / name
    plain = SB.make_run(src, tmp / "plain", "cc", "-O2", "")
    san_flags = " ".join(SB.SANITIZE + SB.COVERAGE + ["-g"])
    san = SB.make_run(src, tmp / "san", clang, "-O1", san_flags, env=SB.san_env())
    x0 = np.asarray(disc.x0, dtype=float)
    xd = np.asarray(disc.disturbance(disc.x0), dtype=float)
    args = [repr(float(v)) for v in list(xd) + list(xd - x0)]
    out = {"name": name, "disc": disc, "tmp": tmp, "plain_main": plain, "san_main": san, "args": args,
           "plain_dir": tmp / "plain", "san_dir": tmp / "san"}
    if plain.returncode == 0 and san.returncode == 0:
        out["plain_driver"] = SB.link_program(tmp / "plain", SB.FUZZ_DIR / "driver.c", tmp / "driver_plain", "cc",
                                              ["-O2"])
        out["san_driver"] = SB.link_program(tmp / "san", SB.FUZZ_DIR / "driver.c", tmp / "driver_san", clang,
                                            ["-O1", "-g"], SB.SANITIZE)
        out["fuzzer"] = SB.link_program(tmp / "san", SB.FUZZ_DIR / "fuzz_solver.c", tmp / f"fuzz_{name}", clang,
                                        ["-O1", "-g"], SB.SANITIZE + ["-fsanitize=fuzzer"])
    return out


NUM = re.compile(r"^[-+]?(\d+\.?\d*([eE][-+]?\d+)?|inf|nan)$", re.IGNORECASE)


def compare_outputs(plain: str, san: str, where: str) -> float:
    """Same lines, same words; numbers with a fractional part equal to ROUND_OFF relative,
    integers (statuses, stage indices) equal. Returns the largest relative difference."""
    a, b = plain.strip().splitlines(), san.strip().splitlines()
    assert len(a) == len(b), f"{where}: {len(a)} lines plain, {len(b)} sanitized"
    worst = 0.0
    for la, lb in zip(a, b):
        wa, wb = la.split(), lb.split()
        assert len(wa) == len(wb), f"{where}: line differs:\n  {la}\n  {lb}"
        for ta, tb in zip(wa, wb):
            if ta == tb:
                continue
            assert NUM.match(ta) and NUM.match(tb) and any(c in ta + tb for c in ".eE"), \
                f"{where}: '{ta}' != '{tb}' in\n  {la}\n  {lb}"
            fa, fb = float(ta), float(tb)
            rel = abs(fa - fb) / max(1.0, abs(fa), abs(fb))
            assert rel <= ROUND_OFF, f"{where}: {fa!r} vs {fb!r} (relative {rel:.2e}) in\n  {la}"
            worst = max(worst, rel)
    return worst


def assert_clean(proc: subprocess.CompletedProcess, where: str) -> None:
    report = SB.sanitizer_report(proc.stderr + proc.stdout)
    assert report is None, f"{where}: sanitizer report:\n{report}"
    assert proc.returncode == 0, f"{where}: exit {proc.returncode}\n{proc.stderr[-3000:]}"


def test_standalone_main_under_sanitizers(built):
    name = built["name"]
    assert_clean(built["plain_main"], f"{name}: make run (plain)")
    assert_clean(built["san_main"], f"{name}: make run (ASan+UBSan)")

    def program_output(proc):   # the main's lines (make -s prints the compiler lines too)
        return "\n".join(l for l in proc.stdout.splitlines()
                         if re.match(r"^(problem|fixed|receding|ok)\b", l))

    plain, san = program_output(built["plain_main"]), program_output(built["san_main"])
    assert plain.endswith("ok") and plain.count("\n") >= 20, plain
    worst = compare_outputs(plain, san, f"{name}: main")
    print(f"\n{name}: make run, plain vs ASan+UBSan: {plain.count(chr(10)) + 1} lines, "
          f"largest relative difference {worst:.1e}")


def test_driver_under_sanitizers(built):
    name = built["name"]
    runs = {}
    for kind in ("plain", "san"):
        proc = subprocess.run([str(built[f"{kind}_driver"]), *built["args"]], capture_output=True, text=True,
                              env=SB.san_env(), timeout=600)
        assert_clean(proc, f"{name}: driver ({kind})")
        runs[kind] = proc.stdout
    worst = compare_outputs(runs["plain"], runs["san"], f"{name}: driver")
    lines = runs["san"].splitlines()
    assert lines[-1] == "ok"
    # the realistic part ran: every iteration of the three phases reached OK
    for phase, count in (("fixed", 8), ("gn", 5), ("receding", 25)):
        statuses = [l.split()[3:6] for l in lines if re.match(rf"^{phase} \d+ status ", l)]
        assert len(statuses) == count, f"{name}: {phase}: {len(statuses)} iterations"
        assert all(s == ["0", "0", "0"] for s in statuses), f"{name}: {phase}: statuses {statuses}"
    # and the closed loop is the plain build's to round-off (already compared): it also moved
    heads = [int(l.split()[-1]) for l in lines if l.startswith("receding ") and " head " in l]
    assert heads == [k % built["disc"].N for k in range(1, 26)]
    bad = {l.split()[1]: int(l.split()[2]) for l in lines if l.startswith("bad ")}
    assert set(bad) == set(BAD_INPUTS), set(bad) ^ set(BAD_INPUTS)
    has_p = built["disc"].np > 0
    for label, want in BAD_INPUTS.items():
        if isinstance(want, tuple):
            want = want[0] if has_p else want[1]
        assert bad[label] == want, f"{name}: {label}: status {bad[label]}, documented {want}"
    print(f"\n{name}: driver, plain vs ASan+UBSan: largest relative difference {worst:.1e}; "
          f"{len(bad)} C API bad-input calls with their documented statuses")


def _fuzz(built, args, timeout):
    return subprocess.run([str(built["fuzzer"]), *args], capture_output=True, text=True, env=SB.san_env(),
                          timeout=timeout, cwd=str(built["tmp"]))


def test_fuzz_corpus_and_regressions_replay_clean(built):
    """Every checked-in input (seed corpus and the regression inputs of crashes found
    earlier) runs through the harness's contract checks without a violation."""
    inputs = sorted((SB.FUZZ_DIR / "corpus").glob("*")) + sorted((SB.FUZZ_DIR / "regressions").glob("*"))
    inputs = [p for p in inputs if p.is_file() and p.name != "README.md"]
    assert len(inputs) >= 10
    proc = _fuzz(built, ["-runs=1", *map(str, inputs)], 600)
    assert_clean(proc, f"{built['name']}: replay")
    assert proc.stderr.count("Executed ") == len(inputs), proc.stderr[-2000:]


def test_fuzz_bounded_run_is_clean(built):
    name = built["name"]
    work = built["tmp"] / "fuzz_corpus"
    work.mkdir(exist_ok=True)
    args = [f"-max_total_time={FUZZ_SECONDS}", "-seed=1", "-timeout=60", "-rss_limit_mb=2048",
            "-print_final_stats=1", f"-artifact_prefix={built['tmp']}/", str(work), str(SB.FUZZ_DIR / "corpus")]
    proc = _fuzz(built, args, FUZZ_SECONDS + 600)
    found = sorted(built["tmp"].glob("crash-*")) + sorted(built["tmp"].glob("timeout-*"))
    if found:   # kept where the next pytest run does not delete them, and printed
        keep = SB.ROOT / "out" / "fuzz"
        keep.mkdir(parents=True, exist_ok=True)
        kept = []
        for f in found:
            shutil.copy(f, keep / f"{name}-{f.name}")
            kept.append(f"{keep / f'{name}-{f.name}'} ({f.read_bytes().hex()})")
        pytest.fail(f"{name}: the fuzzer found {len(found)} input(s): " + "; ".join(kept) +
                    "\nreplay: FUZZ_TRACE=1 <fuzzer> <input>\n" + proc.stderr[-4000:])
    assert_clean(proc, f"{name}: fuzzing")
    stats = dict(re.findall(r"stat::(\w+):\s+(\d+)", proc.stderr))
    runs, per_s = int(stats["number_of_executed_units"]), int(stats["average_exec_per_sec"])
    assert runs > 0
    print(f"\n{name}: libFuzzer + ASan + UBSan, {FUZZ_SECONDS} s: {runs} executions, {per_s} exec/s, "
          f"peak RSS {stats.get('peak_rss_mb', '?')} MB, corpus {len(list(work.iterdir()))} new inputs")
