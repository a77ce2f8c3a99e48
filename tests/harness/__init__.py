"""Test-only helpers: the QP solver harness (compiles runtime_c/dopus_qp.c for given sizes)
and the QP problem sets with known solutions."""
