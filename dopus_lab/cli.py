"""The lab's verbs of ``dopus-gen``: ``bench`` and ``firmware-report``.

They join the product's verbs through the entry points of the group ``dopus_codegen.verbs``
(pyproject.toml), so that ``dopus_codegen`` never imports the lab; they share the product's
exit codes, messages and setting flags (:mod:`dopus_codegen.verbs`).
"""
from __future__ import annotations

from pathlib import Path

import click

from dopus_codegen.verbs import BadInput, RunFailed, one_line, solver_options

__all__ = ["bench", "firmware_report"]


@click.command()
@click.argument("ocp_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--M", "m_list", default="1,5,full", show_default=True,
              help="Comma-separated values of M; 'full' is the full RTI (M = N-1, always timed: the reference of "
                   "the ratios).")
@click.option("--against", type=click.Choice(["none", "acados"]), default="none", show_default=True,
              help="acados: also time acados (SQP_RTI) on the same OCP file: the fastest working exact-Hessian and "
                   "Gauss-Newton settings (screened), in the same process (needs scripts/setup_acados.sh).")
@click.option("--json", "json_out", type=click.Path(dir_okay=False), default=None, help="Write the results as JSON.")
@click.option("--plot", "plot_out", type=click.Path(dir_okay=False), default=None,
              help="Write a bar chart of the phases (PNG).")
@click.option("--reps", default=300, show_default=True, type=click.IntRange(1, 10**6),
              help="Timed steps at the operating point (and per N with --scaling).")
@click.option("--settle", default=100, show_default=True, type=click.IntRange(0, 10**6),
              help="Untimed closed-loop steps before the operating point is timed.")
@click.option("--steps", default=300, show_default=True, type=click.IntRange(1, 10**6),
              help="Timed steps of the closed loop from the disturbed state.")
@click.option("--kkt-iters", default=60, show_default=True, type=click.IntRange(1, 100000),
              help="Iterations of the fixed-xhat_0 study (iterations to KKT 1e-6 and 1e-8 per M).")
@click.option("--scaling", "scaling", default=None,
              help="Comma-separated horizon lengths N (e.g. 20,40,80,160): time per iteration against N at the "
                   "same interval, fitted exponent; replaces the other studies.")
@click.option("--cond", default="40,20,10,8,5,4,2", show_default=True,
              help="acados partial-condensing horizons to screen (with --against acados; with HPIPM's four modes, "
                   "QP tolerances 1e-6, 1e-8 and ours, both Riccati recursions, ERK or the same RK4 map as "
                   "discrete dynamics, -O2 or -O3 -march=native).")
@click.option("--block", default=1, show_default=True, type=click.IntRange(1, 10**6),
              help="The timed settings alternate every BLOCK sampling steps (1: every step, each step starting "
                   "with the caches the others left; e.g. 10: a setting's data stays in the caches between its "
                   "steps, as on a core that runs the controller alone).")
@click.option("--opt", default=None,
              help="Compile flags of our library for the timed runs (e.g. '-O3 -march=native', as acados' fastest "
                   "build variant) [default: the generated default, -O3].")
@click.option("--quick", is_flag=True, help="acados: fewer settings and closed-loop steps (a smoke run).")
@click.option("--work", type=click.Path(file_okay=False), default=None,
              help="Folder for the plan, acados' builds and the export [default: a folder in the temp dir].")
@solver_options("0: the paper's literal QP",
                 names=("hessian", "regularization", "reg_eps", "cost_hessian", "lm"))
def bench(ocp_file, m_list, against, json_out, plot_out, reps, settle, steps, kkt_iters, scaling, cond, block, opt,
          quick, work, hessian, regularization, reg_eps, cost_hessian, lm):
    """Time per iteration of the generated solver on OCP_FILE, by phase, for several M.

    Both at the operating point (the closed loop from the nominal solution, after it has
    settled) and along the closed loop from the disturbed state, every setting interleaved
    step by step in one process that loads only the compiled libraries: feedback latency
    (QP + step), preparation split by the runtime's timers, medians and 10/90 percentiles,
    ratios to our full RTI, the CPU model and the load; and the fixed-xhat_0 iterations to
    KKT 1e-6 and 1e-8 per M. Progress goes to stderr, the table to stdout.
    """
    from dopus_codegen.problem.ocp import OcpError
    from dopus_codegen.settings import SettingError

    from .bench import BenchError, format_scaling, format_table, run_bench, run_scaling

    cli = dict(hessian=hessian, regularization=regularization, reg_eps=reg_eps, cost_hessian=cost_hessian, lm=lm)
    echo = lambda text: click.echo(text, err=True)  # noqa: E731
    try:
        if scaling:
            res = run_scaling(ocp_file, scaling, m_list=m_list if m_list != "1,5,full" else "1,full",
                              json_out=json_out, plot_out=plot_out, reps=reps, settle=settle, work=work,
                              echo=echo, **cli)
            click.echo(format_scaling(res))
            return
        try:
            cond_list = [int(c) for c in cond.split(",")]
        except ValueError:
            raise BenchError(f"--cond: expected comma-separated integers, got {cond!r}") from None
        res = run_bench(ocp_file, m_list=m_list, against=None if against == "none" else against, json_out=json_out,
                        plot_out=plot_out, reps=reps, steps=steps, settle=settle, kkt_iters=kkt_iters,
                        cond_list=cond_list, quick=quick, work=work, echo=echo, block=block, opt=opt, **cli)
    except (OcpError, SettingError) as exc:
        raise BadInput(str(exc)) from None
    except (BenchError, ValueError) as exc:
        raise click.ClickException(str(exc)) from None
    click.echo(format_table(res))


@click.command("firmware-report")
@click.argument("ocp_file", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False), default="out/firmware",
              show_default=True, help="Folder of the generated code, the builds and the images.")
@click.option("--target", "targets", default="m7-double", show_default=True,
              help="Comma-separated targets: m7-double, m7-float (QEMU mps2-an500), m4f-float (mps2-an386, "
                   "single-precision FPU); a float target runs the folder generated with real='float'.")
@click.option("--iters", default=12, show_default=True, type=click.IntRange(1, 1000),
              help="Iterations of the fixed-xhat_0 study per M (M = 1 and the full RTI).")
@click.option("--steps", default=20, show_default=True, type=click.IntRange(1, 10000),
              help="Steps of the closed loop against the generated integrator.")
@click.option("--json", "json_out", type=click.Path(dir_okay=False), default=None,
              help="Write the report as JSON (default: OUTPUT/firmware_report.json).")
def firmware_report(ocp_file, out_dir, targets, iters, steps, json_out):
    """Run the generated solver of OCP_FILE on emulated Cortex-M cores and report sizes and counts.

    Builds the firmware program of firmware/ (bare metal, no heap, semihosting output) with
    arm-none-eabi-gcc, runs it under qemu-system-arm with instruction counting and the same
    program on the host, and prints flash, RAM (data + bss + the stack of one iteration),
    instructions per DOPUS iteration (M = 1, full RTI) and the difference to the host build.
    Installs the Debian packages it needs when root (scripts/setup_firmware.sh).
    """
    from dopus_codegen.outputs import check_output_dir, check_output_file

    from .firmware import FirmwareError, firmware_report as report_fn, format_table

    tlist = [t.strip() for t in targets.split(",") if t.strip()]
    check_output_dir(out_dir, "--output")
    if json_out is None:
        json_out = str(Path(out_dir) / "firmware_report.json")
    elif Path(json_out).parent != Path(out_dir):
        check_output_file(json_out, "--json")
    try:
        rep = report_fn(ocp_file, out_dir, targets=tlist, fixed_iters=iters, loop_steps=steps,
                        json_out=json_out, progress=click.echo)
    except FirmwareError as exc:
        raise BadInput(one_line(exc)) from None
    click.echo(format_table(rep))
    click.echo(f"JSON: {json_out}")
    bad = {t: v["end_status"] for t, v in rep["targets"].items() if v.get("end_status") not in (0, None)}
    if bad:
        raise RunFailed("the firmware program ended with a non-zero solver status on "
                        + ", ".join(f"{t} (status {st})" for t, st in bad.items()))
