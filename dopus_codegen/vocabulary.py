"""The status and setting codes of the C runtime, read from its headers.

The C enums are the single source of every code the two backends share: ``enum
dopus_status`` (runtime_c/dopus_solver.h), ``enum dopus_qp_status`` (dopus_qp.h), ``enum
dopus_phase`` (dopus_timer.h), ``enum dopus_mode`` and ``enum dopus_hessian``
(dopus_solver.h) and ``enum dopus_regularization`` (dopus_reg.h). They are parsed here,
once and without a C compiler, so the reference backend speaks the same codes when no
library is built. A member added to an enum appears here without a Python edit.

A member's name is its identifier without the ``DOPUS_`` prefix and the tag its enum
shares (``ERR_``, ``QP_``, ``PHASE_``, ...), in lower case: ``DOPUS_ERR_QP`` is ``"qp"``,
``DOPUS_QP_MAX_ITER`` is ``"max_iter"``, ``DOPUS_HESSIAN_GAUSS_NEWTON`` is
``"gauss_newton"``. Members named ``DOPUS_N_*`` count the others and are left out. The
description of a status is the text ``dopus_status_string`` returns for it
(runtime_c/dopus_solver.c), else the comment beside the member.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Dict, Optional, Tuple

__all__ = ["Enum", "parse_enums", "parse_status_strings", "runtime_enums", "generated_enums", "status", "qp_status",
           "phases", "enum", "parse_constants", "constants"]

_COMMENT = re.compile(r"/\*(.*?)\*/", re.S)
_ENUM = re.compile(r"\benum\s+(\w+)\s*\{(.*?)\}\s*;", re.S)
_MEMBER = re.compile(r"^\s*(\w+)\s*(?:=\s*([-+]?(?:0[xX][0-9a-fA-F]+|\d+)))?\s*$")
# a number, or one wrapped in the real-type macros of dopus_real.h: DOPUS_R(1e3) reads 1e3,
# DOPUS_PREC(1e-10, 1e-5) its double value 1e-10 (the reference backend computes in double)
_DEFINE = re.compile(r"^\s*#\s*define\s+(\w+)\s+(?:\w+_(?:R|PREC)\(\s*)?"
                     r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\b", re.M)
_CASE = re.compile(r"case\s+(\w+)\s*:\s*return\s+\"((?:[^\"\\]|\\.)*)\"\s*;")


@dataclass(frozen=True)
class Enum:
    """One C enum: ``codes`` maps a member's name to its value, ``identifiers`` the name to
    the C identifier, ``descriptions`` the value to a short English text."""
    c_name: str
    codes: Dict[str, int]
    identifiers: Dict[str, str]
    descriptions: Dict[int, str]

    def name(self, code: int) -> str:
        """The name of ``code`` (``"unknown(<code>)"`` for a code the enum lacks)."""
        for name, value in self.codes.items():
            if value == int(code):
                return name
        return f"unknown({int(code)})"

    def __getitem__(self, name: str) -> int:
        try:
            return self.codes[name]
        except KeyError:
            raise KeyError(f"enum {self.c_name} has no member {name!r}; it has {sorted(self.codes)}") from None

    def __contains__(self, name: object) -> bool:
        return name in self.codes

    def names(self) -> Tuple[str, ...]:
        """The names in the order of their values."""
        return tuple(sorted(self.codes, key=self.codes.__getitem__))


def _member_name(ident: str, prefix: str) -> str:
    return ident[len(prefix):].lower() if ident.startswith(prefix) else ident.lower()


def _tag(idents, placeholder: str) -> str:
    """The prefix every member of most of the enum carries: ``DOPUS_ERR_`` for the status
    enum (whose ``DOPUS_OK`` lacks it), ``DOPUS_QP_`` for the QP statuses."""
    rest = [i[len(placeholder):] for i in idents if i.startswith(placeholder)]
    words = [r.split("_", 1)[0] + "_" for r in rest if "_" in r]
    if not words:
        return placeholder
    best = max(sorted(set(words)), key=words.count)
    return placeholder + best if words.count(best) * 2 > len(rest) else placeholder


def parse_enums(text: str, placeholder: str = "DOPUS_") -> Dict[str, Enum]:
    """Every ``enum name { ... };`` of a C source text, by C name. Values follow C: an
    explicit ``= value`` or the previous value plus one."""
    out: Dict[str, Enum] = {}
    for m in _ENUM.finditer(text):
        body = m.group(2)
        comments: Dict[str, str] = {}
        members = []
        value = -1
        # comments out of the way first (they may hold commas), then one entry per comma;
        # a member's comment follows it on its line (after its comma, or before the brace)
        notes_of = []

        def _park(c):
            notes_of.append(" ".join(c.group(1).split()))
            return f" @{len(notes_of) - 1}@ "
        entries = _COMMENT.sub(_park, body).split(",")
        pending: Optional[str] = None
        for entry in entries:
            notes = [notes_of[int(i)] for i in re.findall(r"@(\d+)@", entry)]
            code = re.sub(r"@\d+@", " ", entry).strip()
            if pending is not None and notes:   # the comment after "MEMBER = 1,"
                comments.setdefault(pending, notes.pop(0))
            if not code:
                continue
            mm = _MEMBER.match(code)
            if mm is None:
                raise ValueError(f"enum {m.group(1)}: cannot read the member {code!r}")
            ident = mm.group(1)
            value = int(mm.group(2), 0) if mm.group(2) is not None else value + 1
            members.append((ident, value))
            if notes:
                comments.setdefault(ident, notes[0])
            pending = ident
        idents = [i for i, _ in members if not i.startswith(placeholder + "N_")]
        tag = _tag(idents, placeholder)
        codes, identifiers, descriptions = {}, {}, {}
        for ident, val in members:
            if ident not in idents:
                continue
            name = _member_name(ident, tag if ident.startswith(tag) else placeholder)
            if name in codes:
                raise ValueError(f"enum {m.group(1)}: two members named {name!r}")
            codes[name] = val
            identifiers[name] = ident
            descriptions[val] = comments.get(ident, name.replace("_", " "))
        out[m.group(1)] = Enum(m.group(1), codes, identifiers, descriptions)
    return out


def parse_status_strings(text: str) -> Dict[str, str]:
    """``case IDENT: return "text";`` pairs of a C source (the texts of dopus_status_string)."""
    return {ident: bytes(s, "utf-8").decode("unicode_escape") for ident, s in _CASE.findall(text)}


_HEADERS = ("solver.h", "qp.h", "timer.h", "reg.h")


def _read_enums(root: Path, name: str) -> Dict[str, Enum]:
    """The enums of the headers ``<name>_solver.h`` ... in ``root`` (prefix ``<NAME>_``),
    keyed by their placeholder C names (``dopus_status``), with the status texts of
    ``<name>_solver.c``."""
    placeholder = f"{name.upper()}_"
    enums: Dict[str, Enum] = {}
    for header in _HEADERS:
        for c_name, e in parse_enums((root / f"{name}_{header}").read_text(), placeholder).items():
            enums["dopus_" + c_name[len(name) + 1:] if c_name.startswith(name + "_") else c_name] = e
    solver_c = root / f"{name}_solver.c"
    texts = parse_status_strings(solver_c.read_text()) if solver_c.is_file() else {}
    st = enums["dopus_status"]
    desc = {st.codes[n]: texts.get(ident, st.descriptions[st.codes[n]]) for n, ident in st.identifiers.items()}
    enums["dopus_status"] = Enum(st.c_name, st.codes, st.identifiers, desc)
    return enums


@lru_cache(maxsize=None)
def runtime_enums(folder: Optional[str] = None) -> Dict[str, Enum]:
    """The enums of the runtime's headers (``folder``: the runtime_c folder, default the
    installed one), with the status texts of dopus_solver.c; parsed once."""
    from .paths import runtime_c_dir

    return _read_enums(Path(folder) if folder is not None else runtime_c_dir(), "dopus")


@lru_cache(maxsize=None)
def generated_enums(folder: str, name: str) -> Dict[str, Enum]:
    """The same enums read from a generated folder (``<name>_solver.h``, ...: the headers the
    library was compiled from), keyed by their placeholder C names; parsed once."""
    return _read_enums(Path(folder), name)


def enum(c_name: str) -> Enum:
    """One enum of the runtime by its C name (``"dopus_mode"``, ...)."""
    enums = runtime_enums()
    if c_name not in enums:
        raise KeyError(f"the runtime headers declare no enum {c_name}; they declare {sorted(enums)}")
    return enums[c_name]


def status() -> Enum:
    """``enum dopus_status``: the codes every backend call returns or raises."""
    return enum("dopus_status")


def qp_status() -> Enum:
    """``enum dopus_qp_status``: why a QP was not solved."""
    return enum("dopus_qp_status")


def phases() -> Tuple[str, ...]:
    """The timed phases in the order of ``enum dopus_phase`` (the index of the timings of dopus_get_info)."""
    return enum("dopus_phase").names()


def parse_constants(text: str, placeholder: str = "DOPUS_") -> Dict[str, float]:
    """The numeric ``#define PLACEHOLDER_NAME value`` lines of a C header, by ``NAME``
    (the identifier without the placeholder): ``DOPUS_QP_TOL_MAX 1e-2`` is ``"QP_TOL_MAX"``."""
    out: Dict[str, float] = {}
    for ident, value in _DEFINE.findall(text):
        if ident.startswith(placeholder):
            v = float(value)
            out[ident[len(placeholder):]] = int(v) if v.is_integer() and "." not in value and "e" not in value.lower() else v
    return out


@lru_cache(maxsize=None)
def constants() -> Dict[str, float]:
    """The numeric constants of runtime_c/dopus_solver.h, dopus_health.h and dopus_lm.h (the
    safety constants of docs/algorithm.md section 9, the constants of the automatic lm of
    section 10), shared by the reference
    backend: ``constants()["DIVERGENCE_BOX"]``."""
    from .paths import runtime_c_dir

    return parse_constants("\n".join((runtime_c_dir() / f).read_text()
                                     for f in ("dopus_solver.h", "dopus_health.h", "dopus_lm.h")))
