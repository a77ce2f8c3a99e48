"""Code generation: CasADi functions and problem data -> one C99 folder (generate), and
its compilation into shared and static libraries (build)."""
