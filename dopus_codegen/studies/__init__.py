"""Studies that compare the generated solver with other tools (acados, scaling, examples)."""
