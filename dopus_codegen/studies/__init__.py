"""Studies on a generated or reference solver: convergence at a fixed initial state
(converge), closed loop against a CVODES plant (sil, plant), Monte Carlo campaigns of closed
loops (campaign, draws), their plots and records."""
