"""The solver settings: one table, one settings value, and where a value came from.

:data:`TABLE` has one row per setting (name, how its value is written, its check, its
default, its help line, and where it belongs). Everything else is derived from it: the
frozen :class:`Settings` value that the OCP file's ``options(...)``, the command line, both
backends and code generation share (its fields are the table's ``solver`` rows), the flags
of the commands, their help texts, the defaults and the validation.

The values of the enumerated settings are those of the C enums (read by
:mod:`dopus_codegen.vocabulary`): ``hessian`` from ``enum dopus_hessian``, ``regularization``
from ``enum dopus_regularization``, ``mode`` from ``enum dopus_mode``, spelled with ``-``
for ``_`` (``"gauss-newton"``). Every setting has exactly one spelling per value; there are
no aliases. ``cost_hessian`` is the flag of ``dopus_set_cost_hessian`` (1 = ``"fresh"``).

Precedence (:func:`resolve`, :meth:`Settings.resolve`): a command-line flag beats the OCP
file's ``options(...)``, which beats the default of the table; both also say which of the
three each value came from (``"cli"``, ``"ocp-file"``, ``"default"``).

The rule on ``M`` (stages re-linearised per iteration, ``0 <= M <= N-1``, above ``N-1``
the full RTI) is :func:`stages`, and nowhere else.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Dict, Mapping, Optional, Tuple

from . import vocabulary

__all__ = ["SettingError", "Setting", "check_adaptive_M", "TABLE", "Settings", "of_problem", "DEFAULTS", "SOLVER_SETTINGS", "FILE_SETTINGS",
           "choices", "code", "value_of", "check", "positive", "nonnegative", "count", "resolve", "stages",
           "RUNTIME_SETTINGS", "HELP", "kind", "validate", "SOURCE_CLI", "SOURCE_FILE", "SOURCE_DEFAULT",
           "parse_m_list", "CAMPAIGN_SETTINGS", "mismatch_table", "REALS", "QP_TOL_DEFAULT", "qp_tol_default",
           "check_real", "KKT_TOL_DEFAULT"]

SOURCE_CLI, SOURCE_FILE, SOURCE_DEFAULT = "cli", "ocp-file", "default"


class SettingError(ValueError):
    """A setting has a value it cannot take; the message names the setting and the value."""


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

_ENUMS = {"budget_unit": "dopus_budget_unit", "hessian": "dopus_hessian", "regularization": "dopus_regularization", "mode": "dopus_mode"}
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


_C_INT_MAX = 2**31 - 1


def _c_int(setting: str, value: int) -> int:
    """``value`` if a C int holds it (the runtime's setters take int)."""
    if value > _C_INT_MAX:
        raise SettingError(f"{setting} must be at most {_C_INT_MAX} (a C int), got {value!r}")
    return value


def _flag(setting: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise SettingError(f"{setting} must be True or False, got {value!r}")
    return value


# --------------------------------------------------------------------------- the table
@dataclasses.dataclass(frozen=True)
class Setting:
    """One row of :data:`TABLE`.

    ``kind``: how the value is written (``choice``, ``positive``, ``nonnegative``, ``lm``,
    ``count``, ``flag``, ``mismatch``); ``check``: the value -> its checked, normalised
    form (:class:`SettingError` otherwise); ``default``: None where the default is not a
    constant (``qp_tol``: the real type's, ``qp_max_iter``: the QP solver's own, ``duration``:
    the scenario's); ``scope``: ``solver`` (a field of :class:`Settings`, set on a backend),
    ``generation`` (code generation) or ``campaign`` (``dopus-gen campaign``); ``file``:
    the OCP file's ``options(...)`` takes it; ``flag``: the verbs that run the solver take
    it as ``--name`` (``M`` has a verb-specific flag, ``mode`` is the verb's own).
    """
    name: str
    kind: str
    check: Callable[[Any], Any]
    default: Any
    help: str
    scope: str = "solver"
    file: bool = False
    flag: bool = False


#: Every setting, one row each; the order is that of ``--help``.
TABLE: Tuple[Setting, ...] = (
    Setting("M", "count", lambda v: count("M", v), 1,
            "Stages re-linearised per iteration (M = N-1 is the full RTI).", file=True),
    Setting("hessian", "choice", lambda v: check("hessian", v), "exact",
            "Hessian of the stage Lagrangians: exact, or Gauss-Newton (needs a least-squares stage cost).",
            file=True, flag=True),
    Setting("regularization", "choice", lambda v: check("regularization", v), "none",
            "Regularisation of the stage Hessian blocks: none, project (eigenvalues floored at reg_eps) or "
            "mirror (absolute values floored at reg_eps).", file=True, flag=True),
    Setting("reg_eps", "positive", lambda v: positive("reg_eps", v), 1e-4,
            "Eigenvalue floor of the regularisation.", file=True, flag=True),
    Setting("cost_hessian", "choice", lambda v: check("cost_hessian", v), "fresh",
            "fresh: the stage-cost Hessian of every stage is recomputed in every iteration; stored: the paper's "
            "literal algorithm (the whole Hessian block moves with its slot; figure 1).", file=True, flag=True),
    Setting("lm", "lm", lambda v: levenberg_marquardt(v), "auto",
            "Levenberg-Marquardt term added to every Hessian block of the QP.", file=True, flag=True),
    Setting("qp_tol", "positive", lambda v: qp_tolerance(v), None,
            "Tolerance of the QP solver on its scaled KKT residuals.", flag=True),
    Setting("qp_max_iter", "count", lambda v: _c_int("qp_max_iter", count("qp_max_iter", v, 1)), None,
            "Iteration limit of the QP solver; reaching it fails the feedback (QP status max_iter). "
            "Not given: the QP solver's own limit.", flag=True),
    Setting("mode", "choice", lambda v: check("mode", v), "receding",
            "receding: shift by one sampling interval in every prepare; fixed: no shift."),
    Setting("budget", "nonnegative", lambda v: nonnegative("budget", v), 0.0,
            "Anytime budget per sampling instant (0: none): the time left after prepare goes to more "
            "re-linearised stages and SQP iterations at the predicted state (docs/algorithm.md section 14).",
            flag=True),
    Setting("budget_unit", "choice", lambda v: check("budget_unit", v), "time",
            "Unit of the budget: time (seconds of the solver's clock) or work (a function evaluation 1, a QP "
            "solve N; deterministic).", flag=True),
    Setting("anytime_tol", "positive", lambda v: positive("anytime_tol", v), None,
            "KKT proxy below which the budget takes no further iteration. Not given: the runtime's (1e-8, float "
            "2e-5).", flag=True),
    Setting("M_adaptive", "flag", lambda v: _flag("M_adaptive", v), False,
            "Adaptive M: each iteration re-linearises the stages whose secant residual exceeds M_eta times the "
            "KKT proxy, between M_min and M_max (docs/algorithm.md section 14)."),
    Setting("M_min", "count", lambda v: count("M_min", v), 0, "Fewest stages of adaptive M."),
    Setting("M_max", "count", lambda v: count("M_max", v), None, "Most stages of adaptive M (not given: N-1)."),
    Setting("M_eta", "positive", lambda v: positive("M_eta", v), 0.1, "Threshold of adaptive M."),
    Setting("gate", "nonnegative", lambda v: nonnegative("gate", v), 0.0,
            "Measurement gate (0: off): a measurement with some |xhat0_i - x_0,i| above gate times the state's "
            "scale (x_0 the state the plan predicts) is handled as a missing one, for at most gate_hold instants "
            "in a row (docs/algorithm.md section 9).", file=True, flag=True),
    Setting("gate_hold", "count", lambda v: _c_int("gate_hold", count("gate_hold", v, 1)), 10,
            "Most measurements in a row the gate holds out; the next is accepted whatever its jump.",
            file=True, flag=True),
    Setting("real", "choice", lambda v: check_real(v), "double",
            "Real-number type of the generated C (runtime, glue and CasADi functions): double or float.",
            scope="generation", file=True),
    Setting("offline_guess", "flag", lambda v: _flag("offline_guess", v), False,
            "Solve the OCP with IPOPT at its initial state at generation and carry the solution.",
            scope="generation", file=True),
    Setting("kkt_tol_rel", "positive", lambda v: positive("kkt_tol_rel", v), None,
            "Relative KKT tolerance of converge and sil: converged once the relative KKT measure (each part "
            "divided by the size of the multipliers or of the iterate, docs/algorithm.md section 6) reaches it. "
            "Not given: the absolute --tol.", scope="study", file=True),
    Setting("runs", "count", lambda v: count("runs", v, 1), 100,
            "Closed-loop runs of the campaign (run i uses the random draw of (seed, i)).", scope="campaign"),
    Setting("seed", "count", lambda v: count("seed", v, 0, 2**63 - 1), 0,
            "Seed of the campaign's random draws.", scope="campaign"),
    Setting("duration", "positive", lambda v: positive("duration", v), None,
            "Simulated seconds per run.", scope="campaign"),
    Setting("threshold", "positive", lambda v: positive("threshold", v), None,
            "A run is on the path when its on-path signal stays at or below this (the signal's unit) ...",
            scope="campaign"),
    Setting("settle", "nonnegative", lambda v: nonnegative("settle", v), None,
            "... from this many seconds after the start and after every push.", scope="campaign"),
    Setting("mismatch", "mismatch", mismatch_table, None,
            "Plant mismatch: quantity=relative half-width pairs, e.g. m1=0.1,m2=0.1 (+-10 %), or none.",
            scope="campaign"),
)

ROWS: Dict[str, Setting] = {row.name: row for row in TABLE}

#: Defaults of every setting (None: not a constant, see :class:`Setting`). The generated
#: runtime's defaults are the OCP file's options, which start from these.
DEFAULTS: Dict[str, Any] = {row.name: row.default for row in TABLE}
#: One line of help per setting (the command line's ``--help``).
HELP: Dict[str, str] = {row.name: row.help for row in TABLE}
#: The fields of :class:`Settings`: what a backend is set to.
SOLVER_SETTINGS = tuple(row.name for row in TABLE if row.scope == "solver")
#: What the OCP file's ``options(...)`` takes.
FILE_SETTINGS = tuple(row.name for row in TABLE if row.file)
#: The settings a verb that runs the solver takes as flags (``--qp-tol`` for ``qp_tol``).
RUNTIME_SETTINGS = tuple(row.name for row in TABLE if row.flag)
#: The settings of ``dopus-gen campaign`` beyond the solver's; the OCP file's ``campaign(...)``
#: (``on_path`` for ``threshold`` and ``settle``) gives their defaults, flags override them.
CAMPAIGN_SETTINGS = tuple(row.name for row in TABLE if row.scope == "campaign")


def _row(setting: str) -> Setting:
    row = ROWS.get(setting)
    if row is None:
        raise SettingError(f"unknown setting {setting!r}; the settings are {sorted(ROWS)}")
    return row


def kind(setting: str) -> str:
    """How a setting's value is written: ``"choice"``, ``"positive"``, ``"nonnegative"``,
    ``"lm"`` (``auto`` or a number >= 0), ``"count"``, ``"flag"`` or ``"mismatch"``."""
    return _row(setting).kind


def validate(setting: str, value: Any) -> Any:
    """The checked (normalised) value of any setting of :data:`TABLE`."""
    return _row(setting).check(value)


def stages(M: Any, N: int, strict: bool = False) -> int:
    """The stages re-linearised per iteration on a horizon of ``N`` intervals: ``M``
    (an integer >= 0, or ``"full"`` for the full RTI) bounded by ``N-1``. A larger ``M``
    is the full RTI, or with ``strict`` a :class:`SettingError`."""
    if M == "full":
        return int(N) - 1
    M = count("M", M)
    if M > int(N) - 1:
        if strict:
            raise SettingError(f"M = {M} exceeds N-1 = {int(N) - 1} (use 'full' for the full RTI)")
        return int(N) - 1
    return M


# --------------------------------------------------------------------------- the value
class _SettingsValue:
    """The behaviour of :class:`Settings` (its fields come from :data:`TABLE`)."""

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if v is not None or ROWS[f.name].default is not None:
                object.__setattr__(self, f.name, ROWS[f.name].check(v))

    def replace(self, **changes) -> "Settings":
        """A copy with ``changes`` (checked); a change given as None is not given."""
        given = {k: v for k, v in changes.items() if v is not None}
        for name in given:
            if name not in SOLVER_SETTINGS:
                raise SettingError(f"unknown setting {name!r}; the settings of a solver are {list(SOLVER_SETTINGS)}")
        return dataclasses.replace(self, **given) if given else self

    def as_dict(self) -> Dict[str, Any]:
        return {name: getattr(self, name) for name in SOLVER_SETTINGS}

    def stages(self, N: int) -> int:
        """``M`` on a horizon of ``N`` intervals (:func:`stages`)."""
        return stages(self.M, N)

    def qp_tol_of(self, real: str = "double") -> float:
        """The QP tolerance: the one set, else the default of the real type."""
        return qp_tol_default(real) if self.qp_tol is None else self.qp_tol

    @classmethod
    def of(cls, values: Optional[Mapping[str, Any]] = None) -> "Settings":
        """The settings of ``values`` (a mapping of any settings; those of other scopes are
        ignored), the defaults for the rest."""
        return cls(**{k: v for k, v in dict(values or {}).items() if k in SOLVER_SETTINGS and v is not None})

    @classmethod
    def resolve(cls, declared: Optional[Mapping[str, Any]], flags: Optional[Mapping[str, Any]],
                real: Optional[str] = None) -> Tuple["Settings", Dict[str, str]]:
        """The settings of a command: its ``flags`` (None: not given) over the OCP file's
        ``declared`` options over the defaults, and where each came from. A QP tolerance
        not given is the default of ``real``."""
        values, sources = resolve(declared, {k: v for k, v in dict(flags or {}).items() if k in SOLVER_SETTINGS},
                                  names=SOLVER_SETTINGS)
        if sources["qp_tol"] == SOURCE_DEFAULT and real is not None:
            values["qp_tol"] = qp_tol_default(real)
        return cls(**values), sources

    def __str__(self) -> str:
        return describe(self.as_dict())


Settings = dataclasses.make_dataclass(
    "Settings", [(row.name, Any, dataclasses.field(default=row.default)) for row in TABLE if row.scope == "solver"],
    bases=(_SettingsValue,), frozen=True, namespace={"__module__": __name__})


def of_problem(disc: Any) -> "Settings":
    """The settings of the OCP file's ``options(...)`` of a problem (a ``Discretized``);
    the defaults for an object without options."""
    options = getattr(getattr(disc, "spec", None), "options", None)
    return options.settings if options is not None else Settings()


Settings.__doc__ = """The settings of a solver, one frozen value (fields: :data:`SOLVER_SETTINGS`, the
``solver`` rows of :data:`TABLE`, checked on construction). ``qp_tol`` None: the default of
the real type the solver is generated in; ``qp_max_iter`` None: the QP solver's own limit.
``Settings(hessian="gauss-newton", M=3)``; ``s.replace(M=1)``."""


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


def describe(values: Mapping[str, Any], sources: Optional[Mapping[str, str]] = None) -> str:
    """One line: ``hessian gauss-newton (ocp-file), M 3 (cli), ...`` (without the sources
    when none are given)."""
    def text(k):
        v = values[k]
        src = f" ({sources[k]})" if sources is not None else ""
        if v is None:
            return f"{k} the solver's own{src}"
        return f"{k} {v:g}{src}" if isinstance(v, float) else f"{k} {v}{src}"
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


def check_adaptive_M(on, M_min, M_max, eta, N):
    """(on, M_min, M_max, eta) of adaptive M, checked: 0 <= M_min <= M_max <= N-1, eta > 0
    (:class:`SettingError` otherwise); shared by both backends."""
    if not isinstance(on, bool) and on not in (0, 1):
        raise SettingError(f"adaptive M: on must be True or False, got {on!r}")
    M_min = count("M_min", M_min)
    M_max = count("M_max", M_max, M_min, N - 1)
    return bool(on), M_min, M_max, positive("eta", eta)
