"""dopus-codegen: fixed-size C99 NMPC solvers running DOPUS, generated from CasADi OCPs."""
__version__ = "0.1.0"
