"""The solver settings: names, allowed values, defaults, validation and where a value came from.

One table for the OCP file's ``options(...)``, the command line, both backends and code
generation. The values of the enumerated settings are those of the C enums (read by
:mod:`dopus_codegen.vocabulary`): ``hessian`` from ``enum dopus_hessian``, ``regularization``
from ``enum dopus_regularization``, ``mode`` from ``enum dopus_mode``, spelled with ``-``
for ``_`` (``"gauss-newton"``). Every setting has exactly one spelling per value; there are
no aliases. ``cost_hessian`` is the flag of ``dopus_set_cost_hessian`` (1 = ``"fresh"``).

Precedence (:func:`resolve`): a command-line flag beats the OCP file's ``options(...)``,
which beats the default here; :func:`resolve` also says which of the three each value came
from (``"cli"``, ``"ocp-file"``, ``"default"``).
"""
from __future__ import annotations

import math
from typing import Any, Dict, Mapping, Optional, Tuple

from . import vocabulary

__all__ = ["SettingError", "DEFAULTS", "SOLVER_SETTINGS", "choices", "code", "value_of", "check",
           "positive", "nonnegative", "count", "resolve", "RUNTIME_SETTINGS", "HELP", "kind", "validate",
           "SOURCE_CLI", "SOURCE_FILE", "SOURCE_DEFAULT", "parse_m_list", "CAMPAIGN_SETTINGS", "mismatch_table",
           "REALS", "QP_TOL_DEFAULT", "qp_tol_default", "check_real", "KKT_TOL_DEFAULT"]

SOURCE_CLI, SOURCE_FILE, SOURCE_DEFAULT = "cli", "ocp-file", "default"


class SettingError(ValueError):
    """A setting has a value it cannot take; the message names the setting and the value."""


#: Defaults of every setting (the generated runtime's defaults come from the OCP file,
#: which starts from these).
DEFAULTS: Dict[str, Any] = {
    "M": 1,
    "hessian": "exact",
    "regularization": "none",
    "reg_eps": 1e-4,
    "cost_hessian": "fresh",
    "lm": "auto",
    "mode": "receding",
    "qp_tol": 1e-10,
    "offline_guess": False,
    "real": "double",
    "runs": 100,
    "seed": 0,
}

#: The real-number types a solver can be generated in (``options(real=...)``,
#: ``--real``), with the value of the generated macro ``<NAME>_REAL_FLOAT``.
REALS = {"double": 0, "float": 1}

#: The default QP tolerance of each real type (the generated ``DOPUS_DEFAULT_QP_TOL``,
#: runtime_c/dopus_solver.c): single precision resolves the scaled KKT residuals of the
#: robot arm's QPs to about 1e-6, so 1e-10 is out of reach there (docs/algorithm.md).
QP_TOL_DEFAULT = {"double": 1e-10, "float": 1e-5}

#: The KKT measure at which a run of ``dopus-gen converge`` counts as converged, per real
#: type: float's floor on the robot arm is 6e-6 to 8e-6 (docs/algorithm.md section 11).
KKT_TOL_DEFAULT = {"double": 1e-8, "float": 2e-5}


def qp_tol_default(real: str) -> float:
    """The default QP tolerance of a solver generated in ``real``."""
    return QP_TOL_DEFAULT[check_real(real)]


def check_real(value: Any) -> str:
    """``value`` if it is a real type of :data:`REALS`, else :class:`SettingError`."""
    if not isinstance(value, str) or value not in REALS:
        raise SettingError(f"real must be {_quote_list(list(REALS))}, got {value!r}")
    return value

#: The settings of a DOPUS backend that an OCP file and the commands share.
SOLVER_SETTINGS = ("M", "hessian", "regularization", "reg_eps", "cost_hessian", "lm")

_ENUMS = {"hessian": "dopus_hessian", "regularization": "dopus_regularization", "mode": "dopus_mode"}
_COST_HESSIAN = {"stored": 0, "fresh": 1}


def _table(setting: str) -> Dict[str, int]:
    if setting == "cost_hessian":
        return dict(_COST_HESSIAN)
    if setting not in _ENUMS:
        raise KeyError(f"{setting!r} is not an enumerated setting; those are {sorted([*_ENUMS, 'cost_hessian'])}")
    e = vocabulary.enum(_ENUMS[setting])
    return {name.replace("_", "-"): value for name, value in e.codes.items()}


def choices(setting: str) -> Tuple[str, ...]:
    """The allowed values of an enumerated setting, in the order of their C codes."""
    t = _table(setting)
    return tuple(sorted(t, key=t.__getitem__))


def _quote_list(values) -> str:
    values = [repr(v) for v in values]
    return values[0] if len(values) == 1 else ", ".join(values[:-1]) + " or " + values[-1]


def check(setting: str, value: Any) -> str:
    """``value`` if it is one of :func:`choices`, else :class:`SettingError`."""
    allowed = choices(setting)
    if not isinstance(value, str) or value not in allowed:
        raise SettingError(f"{setting} must be {_quote_list(allowed)}, got {value!r}")
    return value


def code(setting: str, value: Any) -> int:
    """The C code of an enumerated setting's value (checked)."""
    return _table(setting)[check(setting, value)]


def value_of(setting: str, c_code: int) -> str:
    """The value of an enumerated setting whose C code is ``c_code``."""
    for name, value in _table(setting).items():
        if value == int(c_code):
            return name
    raise SettingError(f"{setting}: the C code {c_code!r} is none of {_table(setting)}")


def _number(setting: str, value: Any, kind: str) -> float:
    if isinstance(value, bool):
        raise SettingError(f"{setting} must be {kind}, got {value!r}")
    try:
        f = float(value)
    except (TypeError, ValueError, OverflowError):    # OverflowError: an int beyond a double
        raise SettingError(f"{setting} must be {kind}, got {value!r}") from None
    return f


def positive(setting: str, value: Any) -> float:
    """A finite number > 0 (``reg_eps``, ``qp_tol``)."""
    f = _number(setting, value, "a positive number")
    if not math.isfinite(f) or f <= 0:
        raise SettingError(f"{setting} must be positive and finite, got {value!r}")
    return f


def qp_tolerance(value: Any) -> float:
    """A QP tolerance: positive and at most ``DOPUS_QP_TOL_MAX`` (runtime_c/dopus_solver.h,
    docs/algorithm.md section 9); a looser QP would return controls the bounds do not hold."""
    from .vocabulary import constants

    f = positive("qp_tol", value)
    limit = constants()["QP_TOL_MAX"]
    if f > limit:
        raise SettingError(f"qp_tol must be at most {limit:g} (DOPUS_QP_TOL_MAX), got {value!r}")
    return f


def nonnegative(setting: str, value: Any) -> float:
    """A finite number >= 0 (``lm``)."""
    f = _number(setting, value, "a number >= 0")
    if not math.isfinite(f) or f < 0:
        raise SettingError(f"{setting} must be finite and >= 0, got {value!r}")
    return f


#: The value of ``lm`` that selects the automatic term (docs/algorithm.md section 10).
LM_AUTO = "auto"


def levenberg_marquardt(value: Any):
    """``"auto"`` (the automatic, adaptive term) or a fixed term: a finite number >= 0."""
    if isinstance(value, str):
        if value.strip().lower() == LM_AUTO:
            return LM_AUTO
        try:
            value = float(value)
        except ValueError:
            raise SettingError(f"lm must be 'auto' or a number >= 0, got {value!r}") from None
    return nonnegative("lm", value)


def lm_code(value: Any) -> float:
    """The generated default of ``lm``: the fixed term, or -1 for the automatic one."""
    v = levenberg_marquardt(value)
    return -1.0 if v == LM_AUTO else v


def count(setting: str, value: Any, minimum: int = 0, maximum: Any = None) -> int:
    """An integer >= ``minimum`` (``M`` >= 0, ``qp_max_iter`` >= 1) and <= ``maximum``
    (``qp_max_iter``: a C int); numpy integers too."""
    import numbers

    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise SettingError(f"{setting} must be an integer >= {minimum}, got {value!r}")
    if maximum is not None and value > maximum:
        raise SettingError(f"{setting} must be at most {maximum} (a C int), got {value!r}")
    return int(value)


_C_INT_MAX = 2**31 - 1


def mismatch_table(value: Any) -> Dict[str, float]:
    """The plant mismatch of a campaign: plant quantity -> relative half-width in [0, 1).
    Written ``"m1=0.1,m2=0.1"`` on the command line (``"none"``: no mismatch), a dict (or
    (name, width) pairs) in the OCP file. The names are checked against the plant
    quantities by the campaign."""
    if isinstance(value, str):
        text = value.strip()
        if text.lower() == "none":
            return {}
        pairs = []
        for item in text.split(","):
            name, sep, width = item.partition("=")
            if not sep or not name.strip():
                raise SettingError(f"mismatch must be 'name=width,...' or 'none', got {value!r}")
            pairs.append((name.strip(), width.strip()))
    elif isinstance(value, Mapping):
        pairs = list(value.items())
    else:
        try:
            pairs = [(n, w) for n, w in value]
        except (TypeError, ValueError):
            raise SettingError(f"mismatch must be 'name=width,...', 'none' or a dict, got {value!r}") from None
    out: Dict[str, float] = {}
    for name, width in pairs:
        f = _number("mismatch", width, "a number in [0, 1)")
        if not (0 <= f < 1):
            raise SettingError(f"mismatch of {name!r} must be a relative half-width in [0, 1), got {width!r}")
        out[str(name)] = f
    return out


def _c_int(setting: str, value: int) -> int:
    """``value`` if a C int holds it (the runtime's setters take int)."""
    if value > _C_INT_MAX:
        raise SettingError(f"{setting} must be at most {_C_INT_MAX} (a C int), got {value!r}")
    return value


_CHECKS = {
    "M": lambda v: count("M", v),
    "hessian": lambda v: check("hessian", v),
    "regularization": lambda v: check("regularization", v),
    "mode": lambda v: check("mode", v),
    "cost_hessian": lambda v: check("cost_hessian", v),
    "reg_eps": lambda v: positive("reg_eps", v),
    "qp_tol": lambda v: qp_tolerance(v),
    "lm": lambda v: levenberg_marquardt(v),
    "qp_max_iter": lambda v: _c_int("qp_max_iter", count("qp_max_iter", v, 1)),
    "real": lambda v: check_real(v),
    "runs": lambda v: count("runs", v, 1),
    "seed": lambda v: count("seed", v, 0, 2**63 - 1),
    "duration": lambda v: positive("duration", v),
    "threshold": lambda v: positive("threshold", v),
    "settle": lambda v: nonnegative("settle", v),
    "mismatch": mismatch_table,
}

#: The settings of ``dopus-gen campaign`` beyond the solver's, in the order of ``--help``;
#: the OCP file's ``campaign(...)`` (``on_path`` for ``threshold`` and ``settle``) gives
#: their defaults, flags override them. ``duration`` not given is the scenario's.
CAMPAIGN_SETTINGS = ("runs", "seed", "duration", "threshold", "settle", "mismatch")

#: The settings a verb that runs the solver takes as flags (``--qp-tol`` for ``qp_tol``),
#: in the order of ``--help``. ``M`` has a verb-specific form (a list for ``converge``),
#: ``mode`` is the verb's (``converge``: fixed, ``sil``: receding) and ``offline_guess`` is
#: a flag of ``generate``. ``qp_max_iter`` has no entry in :data:`DEFAULTS`: not given, it is
#: the QP solver's own limit of the backend.
RUNTIME_SETTINGS = ("hessian", "regularization", "reg_eps", "cost_hessian", "lm", "qp_tol", "qp_max_iter")

#: One line of help per setting (the command line's ``--help``).
HELP: Dict[str, str] = {
    "M": "Stages re-linearised per iteration (M = N-1 is the full RTI).",
    "hessian": "Hessian of the stage Lagrangians: exact, or Gauss-Newton (needs a least-squares stage cost).",
    "regularization": "Regularisation of the stage Hessian blocks: none, project (eigenvalues floored at "
                      "reg_eps) or mirror (absolute values floored at reg_eps).",
    "reg_eps": "Eigenvalue floor of the regularisation.",
    "cost_hessian": "fresh: the stage-cost Hessian of every stage is recomputed in every iteration; stored: the "
                    "paper's literal algorithm (the whole Hessian block moves with its slot; figure 1).",
    "lm": "Levenberg-Marquardt term added to every Hessian block of the QP.",
    "mode": "receding: shift by one sampling interval in every prepare; fixed: no shift.",
    "qp_tol": "Tolerance of the QP solver on its scaled KKT residuals.",
    "qp_max_iter": "Iteration limit of the QP solver; reaching it fails the feedback (QP status max_iter). "
                   "Not given: the QP solver's own limit.",
    "real": "Real-number type of the generated C (runtime, glue and CasADi functions): double or float.",
    "offline_guess": "Solve the OCP with IPOPT at its initial state at generation and carry the solution.",
    "runs": "Closed-loop runs of the campaign (run i uses the random draw of (seed, i)).",
    "seed": "Seed of the campaign's random draws.",
    "duration": "Simulated seconds per run.",
    "threshold": "A run is on the path when its on-path signal stays at or below this (the signal's unit) ...",
    "settle": "... from this many seconds after the start and after every push.",
    "mismatch": "Plant mismatch: quantity=relative half-width pairs, e.g. m1=0.1,m2=0.1 (+-10 %), or none.",
}


def kind(setting: str) -> str:
    """How a setting's value is written: ``"choice"``, ``"positive"``, ``"lm"`` (``auto`` or a
    number >= 0), ``"count"`` or ``"flag"``."""
    if setting in ("hessian", "regularization", "mode", "cost_hessian", "real"):
        return "choice"
    if setting in ("reg_eps", "qp_tol", "duration", "threshold"):
        return "positive"
    if setting == "settle":
        return "nonnegative"
    if setting == "lm":
        return "lm"
    if setting == "mismatch":
        return "mismatch"
    if setting in ("M", "qp_max_iter", "runs", "seed"):
        return "count"
    if setting == "offline_guess":
        return "flag"
    raise SettingError(f"unknown setting {setting!r}; the settings are {sorted(_CHECKS)}")


def validate(setting: str, value: Any) -> Any:
    """The checked (normalised) value of any setting of :data:`DEFAULTS`."""
    if setting == "offline_guess":
        if not isinstance(value, bool):
            raise SettingError(f"offline_guess must be True or False, got {value!r}")
        return value
    if setting not in _CHECKS:
        raise SettingError(f"unknown setting {setting!r}; the settings are {sorted(_CHECKS)}")
    return _CHECKS[setting](value)


def resolve(file_options: Optional[Mapping[str, Any]], cli: Optional[Mapping[str, Any]],
            names=SOLVER_SETTINGS) -> Tuple[Dict[str, Any], Dict[str, str]]:
    """The effective settings and where each came from.

    ``file_options``: what the OCP file declared with ``options(...)`` (only the options it
    gave); ``cli``: the flags given on the command line (None or absent: not given).
    Returns ``(values, sources)`` with ``sources[name]`` one of ``"cli"``, ``"ocp-file"``,
    ``"default"``.
    """
    file_options = dict(file_options or {})
    cli = {k: v for k, v in (cli or {}).items() if v is not None}
    values, sources = {}, {}
    for name in names:
        if name in cli:
            values[name], sources[name] = validate(name, cli[name]), SOURCE_CLI
        elif name in file_options:
            values[name], sources[name] = validate(name, file_options[name]), SOURCE_FILE
        else:
            values[name], sources[name] = DEFAULTS.get(name), SOURCE_DEFAULT
    if sources.get("qp_tol") == SOURCE_DEFAULT:
        # the default QP tolerance is that of the real type the solver is generated in
        real = values.get("real", cli.get("real", file_options.get("real", DEFAULTS["real"])))
        values["qp_tol"] = qp_tol_default(real)
    return values, sources


def describe(values: Mapping[str, Any], sources: Mapping[str, str]) -> str:
    """One line: ``hessian gauss-newton (ocp-file), M 3 (cli), ...``."""
    def text(k):
        v = values[k]
        if v is None:
            return f"{k} the solver's own ({sources[k]})"
        return f"{k} {v:g} ({sources[k]})" if isinstance(v, float) else f"{k} {v} ({sources[k]})"
    return ", ".join(text(k) for k in values)


def parse_m_list(text: Any) -> list:
    """A list of M values as the command line writes it: ``"1,5,full"`` -> ``[1, 5, "full"]``
    (``full`` is the full RTI, M = N-1); SettingError names a bad item."""
    out: list = []
    for item in str(text).split(","):
        item = item.strip()
        if item == "full":
            out.append("full")
        elif item.isdigit():
            out.append(int(item))
        else:
            raise SettingError(f"'{item}' is neither a non-negative integer nor 'full'")
    return out
