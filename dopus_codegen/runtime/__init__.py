"""The Python handle of a generated solver (cffi): CSolver."""
