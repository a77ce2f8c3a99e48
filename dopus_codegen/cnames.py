"""C names: the identifier rule for every name that reaches C, and the prefix renaming.

A problem name, a state, control or parameter name all become parts of C identifiers
(``<name>_solver``, ``<NAME>_N``) and Python attributes, so one rule applies to all of them:
a C identifier that is neither a C99 keyword, nor ``main``, nor a Python keyword.
"""
from __future__ import annotations

import keyword
import re
from typing import Any, Optional

__all__ = ["PLACEHOLDER", "C_RESERVED", "MAX_NAME_LENGTH", "identifier_problem", "rename_placeholder"]

#: The prefix of every exported symbol of runtime_c/ (renamed to the problem name).
PLACEHOLDER = "dopus"

#: C99 keywords and ``main`` (a generated ``<name>_main.c`` defines it).
C_RESERVED = frozenset(
    "auto break case char const continue default do double else enum extern float for goto if "
    "inline int long register restrict return short signed sizeof static struct switch typedef "
    "union unsigned void volatile while _Bool _Complex _Imaginary main".split()
)

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")

#: The longest name: it becomes part of C identifiers (``<name>_set_qp_max_iter``) and of
#: file names (``<name>_casadi.c``), which compilers, linkers and file systems (255 bytes)
#: must all accept.
MAX_NAME_LENGTH = 64


def identifier_problem(name: Any) -> Optional[str]:
    """None if ``name`` may be used as a name, else why not (``"is not a valid C identifier"``
    or ``"... (a reserved word)"``)."""
    if not isinstance(name, str) or not _IDENT.fullmatch(name):
        return "is not a valid C identifier"
    if len(name) > MAX_NAME_LENGTH:
        return (f"is {len(name)} characters long; at most {MAX_NAME_LENGTH} are allowed (the name becomes "
                "part of C identifiers and file names)")
    if name in C_RESERVED or keyword.iskeyword(name):
        return "is not a valid C identifier (a reserved word)"
    return None


def rename_placeholder(text: str, name: str) -> str:
    """The textual renaming of the runtime: ``dopus_`` -> ``<name>_``, ``DOPUS_`` -> ``<NAME>_``
    (one pass, so a problem name containing the placeholder is not renamed twice)."""
    lower, upper = f"{name}_", f"{name.upper()}_"
    return re.sub(r"dopus_|DOPUS_", lambda m: lower if m.group(0) == "dopus_" else upper, text)
