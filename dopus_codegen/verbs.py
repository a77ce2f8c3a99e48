"""What the verbs of ``dopus-gen`` share: the exit codes and their errors, one-line
messages, and the flags of the settings (:mod:`dopus_codegen.settings`).

:mod:`dopus_codegen.cli` defines the product's verbs with these; a package that adds its own
verbs to ``dopus-gen`` (entry points of the group ``dopus_codegen.verbs``, as the lab does in
``dopus_lab/cli.py``) uses the same.
"""
from __future__ import annotations

import click

from . import settings
from .settings import SettingError, choices, validate

__all__ = ["FROM_FILE", "EXIT_FAILED", "EXIT_BAD_INPUT", "RunFailed", "BadInput", "one_line", "setting_callback",
           "setting_option", "solver_options", "real_option", "runtime_values"]

FROM_FILE = "[default: the OCP file's options(...), else {}]"

#: Exit codes: 0 done; 1 the verb ran and what it was asked to do failed (a run of the
#: study failed, the plant of a closed loop could not be integrated); 2 bad input or an
#: environment that does not allow the work (a message names the problem), also click's
#: usage errors; 130 (interrupt.EXIT_INTERRUPTED) stopped by Ctrl-C (SIGINT), any verb.
EXIT_FAILED, EXIT_BAD_INPUT = 1, 2


class RunFailed(click.ClickException):
    """The verb ran, but what it was asked to do failed (exit code 1)."""
    exit_code = EXIT_FAILED


class BadInput(click.ClickException):
    """Bad input or an environment that does not allow the work (exit code 2)."""
    exit_code = EXIT_BAD_INPUT


def one_line(exc: BaseException) -> str:
    """The message of an exception on one line (CasADi's source locations dropped)."""
    from .problem.ocp import casadi_message

    # CasADi raises plain RuntimeErrors; the project's own errors (a failed compile names
    # the CasADi file and must keep the compiler's diagnostic) are shown whole
    text = casadi_message(exc) if type(exc) is RuntimeError else str(exc).strip()
    if isinstance(exc, OSError) and exc.filename is not None:
        text = f"{exc.strerror or text}: '{exc.filename}'"
    text = " ".join(part.strip() for part in text.splitlines() if part.strip())
    return text or type(exc).__name__


def setting_callback(name):
    """A click callback that checks a flag's value by the settings table (None: not given)."""
    def callback(ctx, param, value):
        if value is None:
            return None
        try:
            return validate(name, value)
        except SettingError as exc:
            raise click.BadParameter(str(exc)) from None
    return callback


def setting_option(name: str, note: str = ""):
    """The flag of one runtime setting of dopus_codegen.settings (type, check and help from there)."""
    flag = "--" + name.replace("_", "-")
    kind = settings.kind(name)
    default = settings.DEFAULTS.get(name)
    if name in settings.FILE_SETTINGS:
        where = FROM_FILE.format(default if not isinstance(default, float) else f"{default:g}")
    elif name == "qp_tol":
        where = "[default: " + ", ".join(f"{v:g} in {r}" for r, v in settings.QP_TOL_DEFAULT.items()) + "]"
    elif default is None:
        where = "[default: the QP solver's own]"
    else:
        where = f"[default: {default:g}]" if isinstance(default, float) else f"[default: {default}]"
    help_text = " ".join(t for t in (settings.HELP[name], note, where) if t)
    if kind == "choice":
        return click.option(flag, name, type=click.Choice(choices(name)), default=None, help=help_text)
    ptype = {"positive": float, "nonnegative": float, "lm": str, "count": int}[kind]
    return click.option(flag, name, type=ptype, default=None, callback=setting_callback(name), help=help_text)


def solver_options(lm_note: str, names=None):
    """The runtime settings of dopus_codegen.settings (``names``, default RUNTIME_SETTINGS) as
    flags of a verb that runs the solver; the solver settings default to the OCP file's
    options(...)."""
    names = settings.RUNTIME_SETTINGS if names is None else names
    opts = [setting_option(name, lm_note if name == "lm" else "") for name in names]

    def apply(fn):
        for opt in reversed(opts):
            fn = opt(fn)
        return fn
    return apply


def real_option(what: str):
    """``--real``: the real-number type of the generated C (dopus_codegen.settings.REALS)."""
    return click.option("--real", "real", type=click.Choice(list(settings.REALS)), default=None,
                        help=f"{settings.HELP['real']} {what} [default: the OCP file's options(real=...), "
                             f"else {settings.DEFAULTS['real']}]")


def runtime_values(kwargs: dict) -> dict:
    """The runtime settings of a verb's keyword arguments (None: not given)."""
    return {name: kwargs.pop(name) for name in settings.RUNTIME_SETTINGS}
