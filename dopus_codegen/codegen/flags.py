"""The C compiler flags of the project, in one place.

Every compilation reads them from here: the Python build (:mod:`.build`), the rendered
Makefile and CMake fragment, the QP test harness, the benchmarks and the tests that
compile a runtime file alone.
"""
from __future__ import annotations

#: The runtime and the generated glue: C99, warning-free, pedantic.
STRICT_CFLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
#: The CasADi file gets the same flags: its unused parameters are marked as such when it is
#: generated (generate.silence_unused_parameters).
CASADI_CFLAGS = STRICT_CFLAGS
#: The default optimisation level of a build (``dopus-gen build --opt``, the Makefile's OPT,
#: the CMake fragment's <NAME>_OPT). No -march: add the target's flags (e.g. --opt "-O3
#: -march=native" on the build machine, EXTRA_CFLAGS="-mcpu=cortex-m7 ..." for firmware).
DEFAULT_OPT = "-O3"
#: The optimisation level of the QP test harness and the QP benchmark's harness.
QP_HARNESS_OPT = "-O3"
#: Position-independent code for a shared library.
PIC = "-fPIC"


def cmake_options() -> str:
    """The flags every source of the CMake target gets: STRICT_CFLAGS without the standard,
    which is a target property there."""
    return " ".join(f for f in STRICT_CFLAGS if not f.startswith("-std="))


__all__ = ["STRICT_CFLAGS", "CASADI_CFLAGS", "DEFAULT_OPT", "QP_HARNESS_OPT", "PIC", "cmake_options"]
