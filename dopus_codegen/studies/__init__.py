"""Studies on a generated or reference solver: convergence at a fixed initial state
(converge), closed loop against a CVODES plant (sil, plant), and their plots."""
