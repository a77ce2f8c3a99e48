"""The problem: the OCP file's declarations (ocp), the shooting discretisation (discretize)
and the per-stage CasADi functions of docs/algorithm.md section 2 (derivatives)."""
