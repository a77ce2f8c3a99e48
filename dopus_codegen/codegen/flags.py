"""The C compiler flags of the project, in one place.

Every compilation reads them from here: the Python build (:mod:`.build`), the rendered
Makefile and CMake fragment, the QP test harness, the benchmarks and the tests that
compile a runtime file alone.
"""
from __future__ import annotations

#: The runtime and the generated glue: C99, warning-free, pedantic.
STRICT_CFLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
#: CasADi's generated code has unused parameters in its helpers, so it only gets -Wall.
CASADI_CFLAGS = ("-std=c99", "-Wall")
#: The default optimisation level of a build (``dopus-gen build --opt``, the Makefile's OPT).
DEFAULT_OPT = "-O2"
#: The optimisation level of the QP test harness and the QP benchmark's harness.
QP_HARNESS_OPT = "-O3"
#: Position-independent code for a shared library.
PIC = "-fPIC"


def cmake_strict_options() -> str:
    """STRICT_CFLAGS as the CMake fragment adds them to the strict sources: the standard is a
    target property there and -Wall applies to every source."""
    return ";".join(f for f in STRICT_CFLAGS if not f.startswith("-std=") and f not in CASADI_CFLAGS)


def cmake_common_options() -> str:
    """The flags every source of the CMake target gets (CASADI_CFLAGS without the standard)."""
    return " ".join(f for f in CASADI_CFLAGS if not f.startswith("-std="))


__all__ = ["STRICT_CFLAGS", "CASADI_CFLAGS", "DEFAULT_OPT", "QP_HARNESS_OPT", "PIC",
           "cmake_strict_options", "cmake_common_options"]
