#!/usr/bin/env bash
# Create the separate benchmark environment that carries the HPIPM anchor.
#
# The anchor is HPIPM + BLASFEO as shipped in the PyPI wheel comma-deps-acados
# (BLASFEO built for X64_INTEL_HASWELL, LA_HIGH_PERFORMANCE). The wheel also ships
# a stripped CasADi, so it goes into its own virtualenv (default bench/.env) and is
# never installed next to the project's CasADi. bench/qp_bench.py only takes the
# C headers and shared libraries out of it; no Python module of it is imported.
#
# Usage:  bash bench/setup_hpipm.sh            (idempotent)
# Env:    PYTHON=python3.11  BENCH_ENV=/path/to/env  ACADOS_WHEEL_SPEC='comma-deps-acados==X'
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
env_dir="${BENCH_ENV:-$here/.env}"
python="${PYTHON:-python3}"
# Pinned so that a fresh machine benchmarks the same HPIPM/BLASFEO build.
spec="${ACADOS_WHEEL_SPEC:-comma-deps-acados==0.2.2.post92}"

if [ ! -x "$env_dir/bin/python" ]; then
    echo "creating $env_dir with $("$python" --version 2>&1)"
    "$python" -m venv "$env_dir"
fi
# The environment must never be committed; ignore it from inside (as venv does
# since Python 3.13), so no top-level .gitignore entry is needed.
printf '*\n' > "$env_dir/.gitignore"

"$env_dir/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps "$spec"

site="$("$env_dir/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
root="$site/acados/install"
for f in "$root/lib/libhpipm.so" "$root/lib/libblasfeo.so" \
         "$root/include/hpipm/include/hpipm_d_ocp_qp_ipm.h" \
         "$root/include/blasfeo/include/blasfeo_target.h"; do
    if [ ! -e "$f" ]; then
        echo "setup_hpipm.sh: expected file missing from $spec: $f" >&2
        exit 1
    fi
done
target="$(grep -o 'define TARGET_[A-Z0-9_]*' "$root/include/blasfeo/include/blasfeo_target.h" | head -n1 | cut -d' ' -f2)"
echo "HPIPM anchor ready: $root (BLASFEO $target)"
