"""The Python handle of a generated solver (cffi): Solver."""
