"""The ``dopus-gen`` command line.

Each verb is a thin click wrapper; the work lives in the module named in its
body, imported lazily so that ``dopus-gen --help`` stays fast.
"""
from __future__ import annotations

import click

from . import __version__
from .codegen.flags import DEFAULT_OPT
from .interrupt import EXIT_INTERRUPTED
from .verbs import (EXIT_BAD_INPUT, EXIT_FAILED, BadInput, RunFailed, one_line,  # noqa: F401 - re-exported
                    FROM_FILE as _FROM_FILE, real_option as _real_option, runtime_values as _runtime_values,
                    setting_callback as _setting_callback, solver_options as _solver_options)


class Interrupted(click.ClickException):
    """Stopped by Ctrl-C (SIGINT): one line ``interrupted[: what was kept]`` on stderr,
    exit code 130 (EXIT_INTERRUPTED)."""
    exit_code = EXIT_INTERRUPTED

    def show(self, file=None):
        click.echo(self.format_message(), err=True)


def _interrupted_text(exc: BaseException) -> str:
    detail = str(exc).strip() if isinstance(exc, KeyboardInterrupt) else ""
    return f"interrupted: {detail}" if detail else "interrupted"


class _Group(click.Group):
    """Every exception of a verb becomes a one-line message and exit code 2, unless the
    global ``--debug`` asks for the traceback. Ctrl-C (SIGINT) stops every verb with exit
    code 130 and the line ``interrupted``, also where CasADi caught it and reported a
    failure of its computation instead (:mod:`dopus_codegen.interrupt`)."""

    def invoke(self, ctx):
        from .interrupt import handling

        with handling():
            return self._invoke(ctx)

    def _invoke(self, ctx):
        from .interrupt import interrupted

        def debug():
            return (ctx.obj or {}).get("debug")

        try:
            result = super().invoke(ctx)
        except KeyboardInterrupt as exc:
            if debug():
                raise
            raise Interrupted(_interrupted_text(exc)) from None
        except (click.exceptions.Exit, click.Abort, click.ClickException, SystemExit, Exception) as exc:
            if interrupted() and not debug():
                raise Interrupted("interrupted") from None
            if isinstance(exc, (click.exceptions.Exit, click.Abort, click.ClickException, SystemExit)):
                raise
            if debug():
                raise
            known = _known_errors()
            if isinstance(exc, known):
                raise BadInput(one_line(exc)) from None
            raise BadInput(f"internal error ({type(exc).__name__}): {one_line(exc)} "
                           "(run 'dopus-gen --debug ...' for the traceback)") from None
        if interrupted():   # caught and reported as a failure by CasADi, and the verb went on
            raise Interrupted("interrupted")
        return result


def _known_errors() -> tuple:
    """Errors that describe bad input or the environment (their message is the report)."""
    from .codegen.build import BuildError
    from .codegen.folder import CodegenError
    from .errors import DopusError
    from .problem.ocp import OcpError
    from .settings import SettingError
    from .studies.campaign import CampaignError
    from .studies.plant import PlantError
    from .studies.sil import SilError

    return (OcpError, CodegenError, BuildError, SettingError, DopusError, SilError, PlantError,
            CampaignError, ValueError, OSError)


def _show_warnings(ctx) -> None:
    """Python warnings (a non-smooth model, a CasADi construct) as one 'warning:' line each
    on stderr, for the time of the command."""
    import warnings

    ctx.with_resource(warnings.catch_warnings())
    warnings.simplefilter("default")

    def show(message, category, filename, lineno, file=None, line=None):
        click.echo(f"warning: {message}", err=True)

    warnings.showwarning = show


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="dopus-gen")
@click.option("--cache-dir", type=click.Path(file_okay=False), default=None,
              help="Build cache: compiled objects and the solvers built for --backend c runs. "
                   "[default: $DOPUS_CACHE_DIR, else ~/.cache/dopus-codegen]")
@click.option("--debug", is_flag=True, help="Show the Python traceback of an error instead of the one-line message.")
@click.pass_context
def main(ctx, cache_dir, debug) -> None:
    """Generate, build and run DOPUS NMPC solvers from an OCP file.

    An OCP file is a Python file that defines build() returning a
    dopus_codegen.Ocp (see examples/robot_arm.py).

    Nothing is generated or compiled twice: a folder whose problem is unchanged is not
    regenerated, and every compiled file is kept in the build cache (--cache-dir).

    Exit codes: 0 done; 1 the work ran and failed (a run of converge failed, the
    plant of sil could not be integrated); 2 bad input (a message names the problem;
    --debug shows the traceback instead); 130 interrupted (Ctrl-C).
    """
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug
    _show_warnings(ctx)
    if cache_dir is not None:
        import os

        os.environ["DOPUS_CACHE_DIR"] = str(cache_dir)


def _int_list_or_full(value: str) -> list:
    from .settings import SettingError, parse_m_list

    try:
        return parse_m_list(value)
    except SettingError as exc:
        raise click.BadParameter(str(exc)) from None


@main.command()
@click.argument("ocp_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--M", "m_list", default=None,
              help="Comma-separated values of M (stages re-linearised per iteration); 'full' is the full RTI "
                   "(M = N-1). [default: the OCP file's options(M=...), else full,5,1,0]")
@click.option("--iters", default=40, show_default=True, type=click.IntRange(1, 100000), help="Iterations per run.")
@click.option("--start", type=click.Choice(["cold", "warm"]), default="warm", show_default=True,
              help="cold: the OCP file's initial guess at its initial state; warm: the converged solution at the "
                   "initial state, then iterate for the disturbed initial state.")
@click.option("--tol", default=None, type=click.FloatRange(min=0, min_open=True),
              help="A run has converged when its KKT measure reaches this; the JSON 'solution' is the iterate "
                   "of a converged run. [default: 1e-8, with --real float 2e-5]")
@click.option("--tol-rel", "tol_rel", default=None, type=click.FloatRange(min=0, min_open=True),
              help="A run has converged when its relative KKT measure (docs/algorithm.md section 6) reaches this, "
                   "in place of --tol: for models in physical units. [default: the OCP file's "
                   "options(kkt_tol_rel=...), else not used]")
@_solver_options("0: exact Newton")
@_real_option("With --backend c, the study runs the solver generated in that type (float: see what single "
              "precision costs); the default --qp-tol follows it.")
@click.option("--backend", type=click.Choice(["reference", "c"]), default="reference", show_default=True)
@click.option("--globalise/--no-globalise", "globalise", default=None,
              help="Also run the globalised first solve (docs/algorithm.md section 15: every stage re-linearised, "
                   "a line search on an l1 merit function) from the start. [default: with --start cold]")
@click.option("--json", "json_out", type=click.Path(dir_okay=False), default=None, help="Write the study as JSON.")
@click.option("--plot", "plot_out", type=click.Path(dir_okay=False), default=None, help="Write KKT against iteration as PNG.")
def converge(ocp_file, m_list, iters, start, tol, tol_rel, backend, globalise, json_out, plot_out, real, **kwargs):
    """Fixed-xhat_0 convergence study (paper figure 1): KKT against iteration for each M.

    Exits with 1 when a run failed (an error of the solver or a non-finite KKT measure; the
    globalised solve's too, with what to try), after writing the table, the JSON and the
    plot; a run that did not reach --tol in --iters iterations is reported as not converged
    and is not a failure.
    """
    from .outputs import check_output_file
    from .studies.converge import failed_runs, run_converge_cli

    if json_out:
        check_output_file(json_out, "--json")
    if plot_out:
        check_output_file(plot_out, "--plot")
    study = run_converge_cli(ocp_file=ocp_file, m_list=None if m_list is None else _int_list_or_full(m_list),
                             iters=iters, start=start, backend=backend, json_out=json_out, plot_out=plot_out,
                             tol=tol, tol_rel=tol_rel, real=real, globalise=globalise, **_runtime_values(kwargs))
    bad = failed_runs(study)
    if bad:
        total = len(study["runs"]) + int(study.get("globalised") is not None)
        raise RunFailed(f"{len(bad)} of {total} runs failed: "
                        + "; ".join(f"M = {r['M']}: {r['message']}" for r in bad))


@main.command()
@click.argument("ocp_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--M", "m", default=None, type=click.IntRange(0),
              help="Stages re-linearised per iteration (clamped to N-1, the full RTI). " + _FROM_FILE.format("1"))
@click.option("--duration", default=None, type=click.FloatRange(min=0, min_open=True),
              help="Simulated seconds [default: the scenario's duration].")
@click.option("--json", "json_out", type=click.Path(dir_okay=False), default=None,
              help="Write every run (time series, KKT, timings, settings) as JSON.")
@click.option("--plot-dir", type=click.Path(file_okay=False), default=None, help="Write the PNG figures here.")
@click.option("--compare", type=click.Choice(["none", "full"]), default="none", show_default=True,
              help="full: also run the full RTI (M = N-1) on the same scenario.")
@_solver_options("0: the paper's literal QP; keeps the fixed point, see docs/results.md, Closed loop.")
@_real_option("The closed loop runs the solver generated in that type (float: see what single precision "
              "costs); the default --qp-tol follows it.")
@click.option("--backend", type=click.Choice(["c", "reference"]), default="c", show_default=True)
@click.option("--campaign-run", type=click.IntRange(0), default=None,
              help="Replay run I of the OCP file's campaign (dopus-gen campaign): its initial state, pushes and "
                   "plant mismatch (the file's), with --seed.")
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), default=None,
              help="Seed of the campaign run replayed by --campaign-run. [default: 0]")
def sil(ocp_file, m, duration, json_out, plot_dir, compare, backend, real, campaign_run, seed, **kwargs):
    """Closed loop against a CVODES simulation of the plant (paper figures 2 to 4).

    One DOPUS iteration per sampling instant, started from the offline solution at the
    scenario's initial state; the scenario's events disturb the plant. Exits with 1 when
    a run was aborted (the plant could not be integrated), after the summary, JSON and plots.
    """
    from .outputs import check_output_dir, check_output_file
    from .studies.sil import run_sil_cli

    if json_out:
        check_output_file(json_out, "--json")
    if plot_dir:
        check_output_dir(plot_dir, "--plot-dir")
    if seed is not None and campaign_run is None:
        raise BadInput("--seed needs --campaign-run (it seeds the replayed campaign run)")
    runs = run_sil_cli(ocp_file=ocp_file, M=m, duration=duration, json_out=json_out, plot_dir=plot_dir,
                       compare=compare, backend=backend, echo=click.echo, real=real, campaign_run=campaign_run,
                       seed=seed, **_runtime_values(kwargs))
    aborted = [r for r in runs if r.get("aborted")]
    if aborted:
        raise RunFailed("; ".join(f"run '{r['label']}' aborted after {len(r['t'])} of "
                                  f"{r['result']['instants_planned']} instants: {r['aborted']}" for r in aborted))


def _campaign_option(name: str, flag_type):
    from . import settings

    flag = "--" + name.replace("_", "-")
    default = settings.DEFAULTS.get(name)
    where = ({"duration": "[default: the OCP file's campaign(duration=...), else the scenario's]",
              "threshold": "[default: the OCP file's campaign(on_path=OnPath(...))]",
              "settle": "[default: the OCP file's campaign(on_path=OnPath(...))]",
              "mismatch": "[default: the OCP file's campaign(mismatch=...)]"}.get(name)
             or ("[default: 0]" if name == "seed" else f"[default: the OCP file's campaign({name}=...), else {default}]"))
    return click.option(flag, name, type=flag_type, default=None, callback=_setting_callback(name),
                        help=f"{settings.HELP[name]} {where}")


@main.command()
@click.argument("ocp_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--out", "out", type=click.Path(dir_okay=False), required=True,
              help="The result file (JSON lines, one per run, keyed by run and seed). An existing file of the "
                   "same campaign (its header's fingerprint) is resumed: only the runs it lacks are computed; "
                   "malformed lines are reported and computed again.")
@click.option("--overwrite", is_flag=True,
              help="Start a new campaign in --out when it cannot be resumed (a damaged header, another "
                   "campaign's runs) instead of refusing it.")
@_campaign_option("runs", int)
@_campaign_option("seed", int)
@_campaign_option("duration", float)
@_campaign_option("threshold", float)
@_campaign_option("settle", float)
@_campaign_option("mismatch", str)
@click.option("--workers", default=None, type=int,
              help="Worker processes of the local dask cluster; 0: the runs one by one in this process, no dask. "
                   "[default: one per core]")
@click.option("--scheduler", default=None,
              help="Address of an existing dask scheduler (tcp://host:port) to run on instead of a local cluster; "
                   "its workers need dopus-codegen installed.")
@click.option("--worker-timeout", default=60.0, show_default=True, type=click.FloatRange(min=0, min_open=True),
              help="Seconds without any dask worker after which the campaign stops (resumable); the runs of a "
                   "lost worker are re-submitted to the others.")
@click.option("--M", "m", default=None, type=click.IntRange(0),
              help="Stages re-linearised per iteration (clamped to N-1, the full RTI). " + _FROM_FILE.format("1"))
@_solver_options("0: the paper's literal QP")
@click.option("--backend", type=click.Choice(["c", "reference"]), default="c", show_default=True)
@click.option("--json", "json_out", type=click.Path(dir_okay=False), default=None, help="Write the report as JSON.")
@click.option("--plot-dir", type=click.Path(file_okay=False), default=None,
              help="Write the histograms and the worst runs' trajectories (PNG) here.")
@click.option("--worst", default=4, show_default=True, type=click.IntRange(0, 20),
              help="Runs in the worst-runs figures (simulated again in this process).")
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress display on stderr.")
def campaign(ocp_file, out, overwrite, runs, seed, duration, threshold, settle, mismatch, workers, scheduler,
             worker_timeout, m, backend, json_out, plot_dir, worst, progress, **kwargs):
    """Monte Carlo campaign: many closed-loop runs with random starts, pushes and plant mismatch.

    Run i (with --seed s) is the closed loop of `dopus-gen sil` with the random draw of (s, i):
    plant quantities scaled within the OCP file's campaign(mismatch=...), the initial state
    offset within campaign(initial=...), the pushes of campaign(pushes=Pushes(...)) instead
    of the scenario's events. Reports the runs that stay on the path (campaign(on_path=...)),
    failed instants, recoveries and the time per iteration. Runs on dask.distributed: a local
    cluster (--workers), or an existing scheduler (--scheduler). `dopus-gen sil --campaign-run
    I --seed S` replays one run. Exits with 1 when a run raised an error (the others are
    kept in --out). Ctrl-C, or a dask cluster left without workers (--worker-timeout),
    stops the campaign with the finished runs in --out: the same command computes the others.
    """
    from .studies.campaign import run_campaign

    # run_campaign checks the output paths and --workers before any run
    if scheduler is not None and workers is not None:
        raise BadInput("--workers and --scheduler exclude each other (the scheduler has its own workers)")
    rep = run_campaign(ocp_file, out, workers=workers, scheduler=scheduler, backend=backend, json_out=json_out,
                       plot_dir=plot_dir, echo=click.echo, progress=progress, worst=worst, overwrite=overwrite,
                       worker_timeout=worker_timeout, M=m, runs=runs, seed=seed,
                       duration=duration, threshold=threshold, settle=settle, mismatch=mismatch,
                       **_runtime_values(kwargs))
    if rep["errors"]:
        raise RunFailed(f"{len(rep['errors'])} runs raised an error (the first: run {rep['errors'][0]['run']}: "
                        f"{rep['errors'][0]['message']}); the other runs are in '{out}'")


@main.command()
@click.argument("ocp_file", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Output folder (default: generated/<name> under the current directory). An existing "
                   "folder is replaced only if dopus-gen generated it.")
@click.option("--offline-guess/--no-offline-guess", default=None,
              help="Solve the OCP with IPOPT at its initial state now and carry the primal-dual solution "
                   "as static data (warm start in firmware). Default: the OCP file's options(offline_guess=...).")
@_real_option("")
def generate(ocp_file, out_dir, offline_guess, real):
    """Generate the C99 solver folder of OCP_FILE.

    The folder holds the CasADi functions, sizes and problem data, the renamed runtime,
    a Makefile (`make` builds lib<name>.a, lib<name>.so and main_<name>), a CMake
    fragment and the cffi declarations. Generating twice gives identical bytes.
    """
    from .codegen.generate import generate_file
    from .outputs import check_output_dir

    import time

    check_output_dir(out_dir if out_dir is not None else "generated", "--output")
    t0 = time.time()
    path = generate_file(ocp_file, out_dir, offline_guess=offline_guess, real=real)
    newest = max((p.stat().st_mtime for p in path.iterdir() if p.is_file()), default=0.0)
    click.echo(f"{'generated' if newest >= t0 else 'up to date'}: {path}")
    _echo_soft_summary(path)


def _echo_soft_summary(path) -> None:
    """The soft rows of a generated folder (docs/algorithm.md section 12), from its meta file."""
    from .codegen.folder import read_meta

    meta = read_meta(path)
    if meta.get("soft_rows"):
        click.echo(f"soft rows: {meta['soft_rows']}; the QP is "
                   + ("always feasible (every state-dependent row is soft)" if meta.get("qp_always_feasible")
                      else "not always feasible (some state-dependent row is hard)"))


@main.command()
@click.argument("folder", type=click.Path(file_okay=False))
@click.option("--cc", default="cc", show_default=True, help="C compiler.")
@click.option("--opt", default=None,
              help="Optimisation flags (quoted if several). Default: the flags the folder was last "
                   f"built with, else {DEFAULT_OPT} (no -march; add the target's, e.g. --opt \"-O3 -march=native\").")
@click.option("--force", is_flag=True, help="Rebuild even if the sources did not change.")
def build(folder, cc, opt, force):
    """Compile a generated FOLDER into build/lib<name>.so (cffi) and lib<name>.a (firmware).

    Every file compiles with -std=c99 -Wall -Wextra -Werror -pedantic. Nothing is
    recompiled if sources, compiler and flags are unchanged, and a file compiled before
    (in any folder) comes from the build cache. The products are those of the folder's
    Makefile (FOLDER/build), so `make -C FOLDER run` afterwards only links main_<name>.
    """
    from .codegen.build import build as build_folder

    res = build_folder(folder, cc=cc, opt=opt, force=force)
    state = "built" if res.rebuilt else "up to date"
    click.echo(f"{state}: {res.shared_lib}\n{state}: {res.static_lib}\ncdef: {res.cdef_path}")
    if res.rebuilt:
        click.echo(f"compiled {len(res.compiled)} file(s), the others came from the build cache")


def _add_verbs_of_other_packages() -> None:
    """The verbs other installed packages add to dopus-gen: the entry points of the group
    ``dopus_codegen.verbs`` (the lab's ``bench`` and ``firmware-report``, dopus_lab/cli.py).
    The product itself never imports them."""
    from importlib.metadata import entry_points

    for ep in entry_points(group="dopus_codegen.verbs"):
        if ep.name not in main.commands:
            main.add_command(ep.load(), ep.name)


_add_verbs_of_other_packages()


if __name__ == "__main__":  # pragma: no cover
    main()
