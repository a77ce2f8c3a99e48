"""dopus-gen bench on a small OCP (the unicycle) with few repetitions.

Never a test on timing: the numbers of the bench are checked against independent
measures of the same run (the raw samples it keeps, the runtime's timers inside the wall
clock of the call, the closed loop replayed in this process with CSolver, the iteration
counts of ``dopus-gen converge``, a least-squares fit recomputed with numpy).
"""
from __future__ import annotations

import json

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import EXAMPLES, SECOND_FILE

PREP = ("shift", "gradients", "rho", "hessians", "regularization", "assembly")


@pytest.fixture(scope="module")
def bench_result(tmp_path_factory):
    from dopus_lab.bench import run_bench

    work = tmp_path_factory.mktemp("bench")
    return run_bench(SECOND_FILE, m_list="1,full", reps=25, settle=10, steps=25, kkt_iters=20, work=work,
                     keep_samples=True, json_out=work / "bench.json", plot_out=work / "bench.png"), work


def test_bench_phases_sum_to_the_total(bench_result):
    res, _work = bench_result
    assert res["casadi_imported"] is False
    assert set(res["timed"]) == {"operating point", "closed loop"}
    for phase, t in res["timed"].items():
        samples = res["samples"][phase]
        assert set(t) == {"M=1", "full RTI"}
        for label, rec in t.items():
            s = samples[label]
            fb, pr = np.array(s["feedback"]), np.array(s["prepare"])
            n = 25
            assert fb.size == pr.size == n == rec["steps"]
            tot = fb + pr
            # the reported statistics are those of the kept samples
            assert rec["total_us"]["median"] == pytest.approx(float(np.median(tot)), rel=1e-12)
            assert rec["feedback_us"]["median"] == pytest.approx(float(np.median(fb)), rel=1e-12)
            assert rec["prepare_us"]["p90"] == pytest.approx(float(np.percentile(pr, 90)), rel=1e-12)
            # the runtime's own timers run inside the wall clock of the calls: feedback inside
            # feedback(), the preparation phases (summed) inside prepare()
            for i, ph in enumerate(s["phases"]):
                assert 0.0 < ph["feedback"] <= fb[i] + 1e-3
                prep = sum(ph[k] for k in PREP)
                assert 0.0 < prep <= pr[i] + 1e-3
            assert rec["qp_failures"] == 0
        ref = t["full RTI"]
        assert ref["ratio"] == 1.0 and ref["paired_ratio"]["median"] == 1.0
        m1 = t["M=1"]
        assert m1["ratio"] == pytest.approx(m1["total_us"]["median"] / ref["total_us"]["median"], rel=1e-12)
        ft = np.array(samples["full RTI"]["feedback"]) + np.array(samples["full RTI"]["prepare"])
        mt = np.array(samples["M=1"]["feedback"]) + np.array(samples["M=1"]["prepare"])
        assert m1["paired_ratio"]["median"] == pytest.approx(float(np.median(mt / ft)), rel=1e-12)
        # the runtime's own timers of a step (every phase of feedback and prepare), recomputed
        # from the kept samples, and their ratio in the headline
        tims = {k: np.array([sum(ph.values()) for ph in samples[k]["phases"]]) for k in ("M=1", "full RTI")}
        for k in tims:
            assert t[k]["timers_total_us"]["median"] == pytest.approx(float(np.median(tims[k])), rel=1e-12)
            assert np.all(tims[k] <= np.array(samples[k]["feedback"]) + np.array(samples[k]["prepare"]) + 2e-3)
        assert res["headline"][phase]["M=1 / our full RTI"]["timers_ratio"] == pytest.approx(
            float(np.median(tims["M=1"]) / np.median(tims["full RTI"])), rel=1e-12)
        head = res["headline"][phase]["M=1 / our full RTI"]
        assert head["ratio"] == m1["ratio"] and head["paired_ratio"] == m1["paired_ratio"]["median"]
        assert res["headline"][phase]["feedback latency (us, median)"]["M=1"] == m1["feedback_us"]["median"]
    m = res["machine"]
    assert m["cores"] >= 1 and len(m["loadavg"]) == 3 and m["cpu"]
    on_disk = json.loads((_work / "bench.json").read_text())
    assert on_disk["timed"]["closed loop"]["M=1"]["total_us"]["median"] == res["timed"]["closed loop"]["M=1"][
        "total_us"]["median"]
    assert (_work / "bench.png").stat().st_size > 1000


def test_bench_closed_loop_equals_csolver_replay(bench_result, second_disc, second_solution):
    """The timing process drives the library as CSolver does: the closed loop from the
    disturbed state, replayed here with CSolver and the generated plant, gives the same
    states."""
    from dopus_codegen.runtime.solver import CSolver

    res, _work = bench_result
    disc = second_disc
    guess, _info = second_solution
    xd = np.array(disc.scenario.disturbance(np.array(disc.x0, float).copy()), float)
    p0 = np.asarray(disc.p0, float)
    p0 = p0[0] if p0.ndim > 1 else p0
    for label, M in (("M=1", 1), ("full RTI", disc.N - 1)):
        s = CSolver(disc, M=M, mode="receding", hessian=res["settings"]["hessian"],
                    regularization=res["settings"]["regularization"], lm=res["settings"]["lm"])
        s.init(np.array(disc.x0, float), guess)
        x = xd.copy()
        xs = [x.copy()]
        for _ in range(25):
            u = s.feedback(x)
            s.prepare()
            x = np.array(disc.stage_eval(x, u, p0)[0], float).reshape(-1)
            xs.append(x.copy())
        got = np.array(res["samples"]["closed loop"][label]["x"])
        assert got.shape == (26, disc.nx)
        np.testing.assert_allclose(got, np.array(xs), rtol=1e-9, atol=1e-12)


def test_bench_kkt_iterations_equal_converge(bench_result, tmp_path):
    from dopus_codegen.cli import main
    from dopus_codegen.studies.converge import iterations_to

    res, _work = bench_result
    out = tmp_path / "conv.json"
    r = CliRunner().invoke(main, ["converge", str(SECOND_FILE), "--M", "1,full", "--iters", "20", "--start", "warm",
                                  "--backend", "c", "--json", str(out)])
    assert r.exit_code == 0, r.output
    conv = json.loads(out.read_text())
    assert res["kkt"]["start"] == "warm"
    by_M = {row["M"]: row for row in res["kkt"]["runs"]}
    assert len(conv["runs"]) == 2
    for run in conv["runs"]:
        row = by_M[run["M"]]
        assert row["iters_to_1e-6"] == iterations_to(run["kkt"], 1e-6)
        assert row["iters_to_1e-8"] == iterations_to(run["kkt"], 1e-8)
        assert row["iters_to_1e-8"] is not None      # the study converges on this problem
        assert row["last_kkt"] == pytest.approx(run["kkt"][-1], rel=1e-9, abs=1e-15)


def test_bench_scaling_fit(tmp_path):
    from dopus_codegen.cli import main

    out = tmp_path / "scaling.json"
    r = CliRunner().invoke(main, ["bench", str(SECOND_FILE), "--scaling", "6,12", "--reps", "15", "--settle", "5",
                                  "--json", str(out), "--work", str(tmp_path)])
    assert r.exit_code == 0, r.output
    res = json.loads(out.read_text())
    assert res["casadi_imported"] is False
    assert set(res["scaling"]) == {"converged", "operating point"}
    for phase, fits in res["scaling"].items():
        for key, f in fits.items():
            Ns = [row["N"] for row in f["rows"]]
            assert Ns == [6, 12]
            t = [res["timed"][phase][f"N={row['N']} " + ("full RTI" if key == "full" else key)]
                 ["total_us"]["median"] for row in f["rows"]]
            assert [row["total_us"] for row in f["rows"]] == t
            slope = (np.log(t[1]) - np.log(t[0])) / (np.log(12) - np.log(6))
            assert f["exponent_total"] == pytest.approx(slope, rel=1e-9)
        assert {row["M"] for row in fits["full"]["rows"]} == {5, 11}


@pytest.mark.parametrize("args, message", [
    (["--M", "1,x"], "'x' is neither a non-negative integer nor 'full'"),
    (["--M", "40"], "M = 40 exceeds N-1 = 19"),
    (["--scaling", "1,20"], "'1' is not a horizon length N >= 2"),
    (["--scaling", "20"], "at least two values of N"),
    (["--cond", "10,a"], "--cond: expected comma-separated integers"),
])
def test_bench_bad_input(args, message, tmp_path):
    from dopus_codegen.cli import main

    r = CliRunner().invoke(main, ["bench", str(SECOND_FILE), *args, "--reps", "2", "--steps", "2", "--kkt-iters", "2",
                                  "--work", str(tmp_path)])
    assert r.exit_code != 0
    assert message in r.output
    assert "Traceback" not in r.output
    assert r.exception is None or isinstance(r.exception, SystemExit)


def test_bench_bad_ocp_file(tmp_path):
    from dopus_codegen.cli import main

    bad = tmp_path / "bad.py"
    bad.write_text("def build():\n    return 42\n")
    r = CliRunner().invoke(main, ["bench", str(bad), "--work", str(tmp_path)])
    assert r.exit_code != 0 and "Traceback" not in r.output
    assert "Ocp" in r.output


def test_acados_gets_the_starting_value_of_the_automatic_lm(robot_disc, robot_solution):
    """acados has no automatic Levenberg-Marquardt term: with ours automatic (the default)
    its exact-Hessian settings are screened with the value ours starts from at the nominal
    solution, here checked against the reference implementation's automatic term; a
    numeric lm is passed as it is (before, the default 'auto' stopped `make bench-acados`)."""
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.runtime.solver import build_for
    from dopus_lab.bench import acados_lm

    nominal, _ = robot_solution
    prob = {"disc": robot_disc, "spec": {"folder": str(build_for(robot_disc))}, "nominal": nominal}
    said = []
    lm = acados_lm(prob, {"lm": "auto"}, said.append)
    ref = ReferenceDopus(robot_disc, lm="auto")
    ref.init(np.asarray(robot_disc.x0, float), nominal)
    assert lm > 0 and lm == pytest.approx(ref.lm, rel=1e-12)
    assert "no automatic Levenberg-Marquardt term" in said[0]
    assert acados_lm(prob, {"lm": 3e-4}, said.append) == 3e-4


def test_bench_tracking_is_the_scenario_signal_of_each_loop(bench_result, second_disc):
    """The tracking beside the headline ratios is the scenario's first scalar signal over
    the timed steps of each setting's own closed loop: recomputed here from the kept states
    and controls, which are the plant's (each state the generated model's step from the
    one before under the control that was applied)."""
    res, _work = bench_result
    d = second_disc
    name, fn = next(iter(d.scenario.closed_loop.signals.items()))
    p = np.asarray(d.p0, float).reshape(-1, d.np)[0] if d.np else np.zeros(0)
    for phase, runs in res["trajectories"].items():
        for label, tr in runs.items():
            x, u, skip = np.array(tr["x"]), np.array(tr["u"]), tr["skip"]
            assert len(u) == len(x) - 1 == skip + 25
            for i in range(len(u)):
                phi = np.array(d.stage_eval(x[i], u[i], p)[0]).reshape(-1)
                np.testing.assert_allclose(x[i + 1], phi, rtol=1e-12, atol=1e-12)
            v = np.abs([float(np.asarray(fn(x[i], u[i], p)).reshape(-1)[0]) for i in range(skip, len(u))])
            rec = res["tracking"][phase][label]
            assert rec["signal"] == name
            assert rec["rms"] == pytest.approx(float(np.sqrt(np.mean(v ** 2))), rel=1e-12)
            assert rec["max"] == pytest.approx(float(v.max()), rel=1e-12)
        head = res["headline"][phase]["M=1 / our full RTI"]["tracking"]
        assert head == {"M=1": res["tracking"][phase]["M=1"], "full RTI": res["tracking"][phase]["full RTI"]}


def test_headline_falls_back_to_an_alternate_that_failed_no_qp():
    """A pick that fails a QP in a timed phase gives way to its first alternate without a
    failure (the next fastest working setting of its group); with every candidate failed
    there is no ratio."""
    from dopus_lab.bench import headline

    def rec(med, fails):
        return {"total_us": {"median": med}, "feedback_us": {"median": med / 2}, "qp_failures": fails}

    ex = "acados exact fastest working"
    timed = {"M=1": rec(100.0, 0), "full RTI": rec(200.0, 0), ex: rec(350.0, 1), f"{ex} alternate 1": rec(400.0, 0),
             f"{ex} alternate 2": rec(380.0, 0)}
    picks = {ex: {"label": "A", "qp": {"tol": 1e-10}}, f"{ex} alternate 1": {"label": "B", "qp": {"tol": 1e-10}},
             f"{ex} alternate 2": {"label": "C", "qp": {"tol": 1e-10}}}
    result = {"N": 10, "timed": {"operating point": timed}, "acados_picks": picks}
    row = headline(result)["operating point"]["our full RTI / acados fastest working exact RTI (each at its defaults)"]
    # the first alternate in the pick's order, not the faster second one
    assert row["b"] == f"{ex} alternate 1" and row["acados_setting"] == "B"
    assert row["ratio"] == pytest.approx(200.0 / 400.0)
    timed[f"{ex} alternate 1"]["qp_failures"] = 2
    timed[f"{ex} alternate 2"]["qp_failures"] = 1
    row = headline(result)["operating point"]["our full RTI / acados fastest working exact RTI (each at its defaults)"]
    assert "ratio" not in row and row["failed"] == {"full RTI": 0, ex: 1}


def test_blocks_of_steps_give_the_same_closed_loops(bench_result, tmp_path):
    """--block: the settings alternate every few steps instead of every step; each closed
    loop is its own, so the states and controls are those of the step-by-step run."""
    from dopus_lab.bench import run_bench

    res, _work = bench_result
    blk = run_bench(SECOND_FILE, m_list="1,full", reps=25, settle=10, steps=25, kkt_iters=20, work=tmp_path,
                    keep_samples=True, block=7)
    assert blk["block"] == 7
    for phase, runs in res["trajectories"].items():
        for label, tr in runs.items():
            np.testing.assert_array_equal(np.array(blk["trajectories"][phase][label]["x"]), np.array(tr["x"]))
            np.testing.assert_array_equal(np.array(blk["trajectories"][phase][label]["u"]), np.array(tr["u"]))
            assert blk["timed"][phase][label]["steps"] == 25
    with pytest.raises(Exception, match="--block must be a positive integer"):
        run_bench(SECOND_FILE, m_list="1,full", block=0, work=tmp_path)


def test_opt_builds_a_copy_with_the_flags(bench_result, tmp_path):
    """--opt: our library is built with the given flags in a copy of the cached folder (which
    keeps its default build), and the closed loops follow the default build's closely."""
    from dopus_codegen.codegen.build import recorded_opt
    from dopus_codegen.codegen.flags import DEFAULT_OPT
    from dopus_lab.bench import run_bench

    res, _work = bench_result
    opt = "-O2 -fno-tree-vectorize"
    other = run_bench(SECOND_FILE, m_list="1,full", reps=25, settle=10, steps=25, kkt_iters=20, work=tmp_path,
                      keep_samples=True, opt=opt)
    assert other["ours_opt"] == opt and res["ours_opt"] == DEFAULT_OPT
    # the library lives in the folder's build/ subfolder
    lib = Path(other["library"])
    assert lib.is_relative_to(tmp_path) and recorded_opt(lib.parent.parent) == opt
    assert recorded_opt(Path(res["library"]).parent.parent) == DEFAULT_OPT
    for phase, runs in res["trajectories"].items():
        for label, tr in runs.items():
            np.testing.assert_allclose(np.array(other["trajectories"][phase][label]["x"]), np.array(tr["x"]),
                                       rtol=1e-9, atol=1e-9)


def test_headline_gives_no_ratio_for_a_pair_with_a_qp_failure():
    """A ratio only between settings without a QP failure in any timed phase; ours at its
    default tolerance and at acados' (the matched runs)."""
    from dopus_lab.bench import headline

    def rec(med, fails):
        return {"total_us": {"median": med}, "feedback_us": {"median": med / 2}, "qp_failures": fails}

    result = {"N": 10, "timed": {
        "operating point": {"M=1": rec(100.0, 0), "full RTI": rec(200.0, 0), "M=1 qp_tol 1e-06": rec(80.0, 0),
                            "full RTI qp_tol 1e-06": rec(150.0, 0), "acados GN fastest working": rec(400.0, 0),
                            "acados exact fastest working": rec(300.0, 0)},
        "closed loop": {"M=1": rec(110.0, 0), "full RTI": rec(220.0, 0), "M=1 qp_tol 1e-06": rec(88.0, 0),
                        "full RTI qp_tol 1e-06": rec(165.0, 0), "acados GN fastest working": rec(440.0, 0),
                        "acados exact fastest working": rec(330.0, 1)}},
        "acados_picks": {"acados GN fastest working": {"label": "GN", "qp": {"tol": 1e-6}},
                         "acados exact fastest working": {"label": "exact", "qp": {"tol": 1e-6}}},
        "matched_runs": {"M=1 qp_tol 1e-06": {"of": "M=1", "qp_tol": 1e-6},
                         "full RTI qp_tol 1e-06": {"of": "full RTI", "qp_tol": 1e-6}}}
    for phase, scale in (("operating point", 1.0), ("closed loop", 1.1)):
        h = headline(result)[phase]
        assert h["M=1 / our full RTI"]["ratio"] == pytest.approx(0.5)
        assert h["M=1 / acados fastest working GN RTI (each at its defaults)"]["ratio"] == pytest.approx(0.25)
        assert h["M=1 / acados fastest working GN RTI (equal QP tolerance 1e-06)"]["ratio"] == pytest.approx(0.2)
        for name in ("our full RTI / acados fastest working exact RTI (each at its defaults)",
                     "our full RTI / acados fastest working exact RTI (equal QP tolerance 1e-06)",
                     "M=1 / acados fastest working RTI"):
            row = h[name]
            # the exact-Hessian setting failed a QP in the closed loop: no ratio in any phase
            assert "ratio" not in row and row["failed"]["acados exact fastest working"] == 1, (phase, name)
        assert h["feedback latency (us, median)"]["M=1"] == pytest.approx(50.0 * scale)


def test_bench_of_a_scaled_problem_plants_in_declared_units(tmp_path):
    """examples/cstr.py declares scales (docs/algorithm.md section 16): the generated phi works
    in the solver's variables, the bench's plant in the declared units. Its plant steps IPOPT's
    nominal solution (the declared NLP, the same Radau IIA discretisation) node to node; the
    bench's loops from that solution solve every QP, the closed loop equals CSolver's replayed
    against the declared model, and its first control is IPOPT's at the initial state."""
    from dopus_codegen import build_functions, load_ocp
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.runtime.solver import CSolver, build_for
    from dopus_lab.bench import run_bench
    from dopus_lab.timing import Ours

    path = EXAMPLES / "cstr.py"
    disc = build_functions(load_ocp(path))
    assert disc.scaling is not None
    nominal, info = solve_ocp(disc, disc.x0)
    assert info["success"]
    folder = build_for(disc)
    spec = {"name": disc.name, "folder": str(folder), "N": disc.N, "nx": disc.nx, "nu": disc.nu,
            "p0": np.asarray(disc.p0, float).reshape(-1).tolist()}
    plant = Ours(spec).plant
    xs, us = np.asarray(nominal.x, float), np.asarray(nominal.u, float)
    for k in range(disc.N):
        np.testing.assert_allclose(plant(xs[k], us[k]), xs[k + 1], rtol=1e-8, atol=1e-10)

    res = run_bench(path, m_list="1,full", reps=10, settle=5, steps=15, kkt_iters=5, work=tmp_path,
                    keep_samples=True)
    for phase in ("operating point", "closed loop"):
        for label in ("M=1", "full RTI"):
            assert res["timed"][phase][label]["qp_failures"] == 0, (phase, label)
    xd = np.array(disc.scenario.disturbance(np.array(disc.x0, float).copy()), float)
    for label, M in (("M=1", 1), ("full RTI", disc.N - 1)):
        got = res["samples"]["closed loop"][label]
        s = CSolver(disc, M=M, mode="receding", hessian=res["settings"]["hessian"],
                    regularization=res["settings"]["regularization"], lm=res["settings"]["lm"])
        s.init(np.array(disc.x0, float), nominal)
        x, replay = xd.copy(), [xd.copy()]
        for _ in range(15):
            u = s.feedback(x)
            s.prepare()
            x = np.array(disc.stage_eval(x, u, np.asarray(disc.p0, float).reshape(-1))[0], float).reshape(-1)
            replay.append(x.copy())
        np.testing.assert_allclose(np.array(got["x"]), np.array(replay), rtol=1e-9, atol=1e-12)
    # the operating point's loop starts at the initial state from IPOPT's solution there: its
    # first control and the state it leads to are IPOPT's
    for label in ("M=1", "full RTI"):
        op = res["trajectories"]["operating point"][label]
        np.testing.assert_allclose(op["u"][0], us[0], rtol=1e-6)
        np.testing.assert_allclose(op["x"][1], xs[1], rtol=1e-6)
