"""Studies on a generated or reference solver: convergence at a fixed initial state
(converge), closed loop against a CVODES plant (sil, plant), their plots, and the
comparison with acados on the same OCP file (acados_export, acados_ocp, acados_compare)."""
