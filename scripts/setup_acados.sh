#!/usr/bin/env bash
# Create acados' own virtual environment for the comparison with acados
# (dopus_lab/acados_*.py, bench/acados_bench.py).
#
# The PyPI wheel comma-deps-acados ships compiled acados, HPIPM, BLASFEO and qpOASES
# (acados/install/lib), their headers (acados/install/include), acados' template renderer
# (acados/install/bin/t_renderer), acados' Python template (acados/acados_template) and a
# slimmed CasADi built for CPython 3.12 only. That CasADi replaces the project's, so the
# wheel lives in its own environment (default .venv-acados) and the two never meet in one
# process. acados' template finds its libraries, headers and renderer through
# ACADOS_SOURCE_DIR = <site-packages>/acados/install, which dopus_lab/acados_ocp.py
# sets itself (python -c 'import acados; print(acados.DIR)' prints it).
#
# Usage:  bash scripts/setup_acados.sh          (idempotent; prints the environment's python)
# Env:    ACADOS_VENV=/path/to/env  PYTHON312=/path/to/python3.12
#         ACADOS_WHEEL_SPEC='comma-deps-acados==X'
# Exit 3: no CPython 3.12 could be found or installed (the tests skip with this reason).
set -euo pipefail
cd "$(dirname "$0")/.."

env_dir="${ACADOS_VENV:-.venv-acados}"
# Pinned so that a fresh machine compares against the same acados build.
spec="${ACADOS_WHEEL_SPEC:-comma-deps-acados==0.2.2.post92}"
stamp="$env_dir/.acados-installed"

if [ -x "$env_dir/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$spec" ]; then
    echo "$env_dir/bin/python"
    exit 0
fi

find_python312() {
    local c
    for c in "${PYTHON312:-}" python3.12 /usr/bin/python3.12 /usr/local/bin/python3.12; do
        [ -n "$c" ] || continue
        if command -v "$c" >/dev/null 2>&1 && "$c" -c 'import sys, venv; assert sys.version_info[:2] == (3, 12)' >/dev/null 2>&1; then
            command -v "$c"
            return 0
        fi
    done
    local root
    for root in "${PYENV_ROOT:-}" "$HOME/.pyenv" /root/.pyenv /opt/pyenv; do
        [ -n "$root" ] && [ -d "$root/versions" ] || continue
        for c in $(ls -d "$root"/versions/3.12*/bin/python3.12 2>/dev/null | sort -V -r); do
            if "$c" -c 'import venv' >/dev/null 2>&1; then
                echo "$c"
                return 0
            fi
        done
    done
    return 1
}

py312="$(find_python312 || true)"
if [ -z "$py312" ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    # Debian ships 3.12 only in some releases; try, never fail the caller on it.
    if apt-cache show python3.12-venv >/dev/null 2>&1 || { apt-get update -qq >/dev/null 2>&1 && apt-cache show python3.12-venv >/dev/null 2>&1; }; then
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3.12 python3.12-venv >/dev/null 2>&1 || true
        py312="$(find_python312 || true)"
    fi
fi
if [ -z "$py312" ]; then
    echo "setup_acados.sh: the CasADi in $spec needs CPython 3.12, none found (set PYTHON312=...)" >&2
    exit 3
fi

if [ ! -x "$env_dir/bin/python" ]; then
    echo "setup_acados.sh: creating $env_dir with $("$py312" --version 2>&1)" >&2
    "$py312" -m venv "$env_dir"
fi
# Never committed: ignored from inside, so no top-level .gitignore entry is needed.
printf '*\n' > "$env_dir/.gitignore"
"$env_dir/bin/python" -m pip install --quiet --disable-pip-version-check "$spec" >&2
"$env_dir/bin/python" -c 'import acados; acados.smoketest()' >&2
echo "$spec" > "$stamp"
echo "$env_dir/bin/python"
