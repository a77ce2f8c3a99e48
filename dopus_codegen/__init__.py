"""dopus-codegen: fixed-size C99 NMPC solvers running DOPUS, generated from CasADi OCPs."""
__version__ = "0.1.0"

# The public names are imported lazily so that `dopus-gen --help` does not load CasADi.
_EXPORTS = {
    "Ocp": "problem.ocp", "OcpError": "problem.ocp", "Integrator": "problem.ocp",
    "RK4": "problem.ocp", "GaussLegendre": "problem.ocp", "RadauIIA": "problem.ocp",
    "Event": "problem.ocp", "Pushes": "problem.ocp", "OnPath": "problem.ocp", "Guess": "problem.ocp", "Soft": "problem.ocp",
    "ScenarioSpec": "problem.ocp", "load_ocp": "problem.ocp", "OcpSpec": "problem.spec",
    "Discretized": "problem.derivatives", "build_functions": "problem.derivatives",
    "solve_ocp": "reference.offline",
    "Solver": "runtime.solver", "Settings": "settings", "DopusError": "errors",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name):
    if name in _EXPORTS:
        import importlib

        module = importlib.import_module(f".{_EXPORTS[name]}", __name__)
        value = getattr(module, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'dopus_codegen' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_EXPORTS))
