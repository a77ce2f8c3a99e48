#!/usr/bin/env bash
# Set up everything `make demo` and `make test` need on a fresh Debian machine:
# a C compiler, make and Python 3 with venv (from Debian's packages when we are
# root and they are missing), then the project's virtual environment .venv with
# the package and its test extras. Idempotent: a second run only checks.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v cc >/dev/null 2>&1 || need_apt+=(gcc libc6-dev)
command -v make >/dev/null 2>&1 || need_apt+=(make)
command -v python3 >/dev/null 2>&1 || need_apt+=(python3 python3-venv)
if command -v python3 >/dev/null 2>&1 && ! python3 -c "import venv, ensurepip" >/dev/null 2>&1; then
    need_apt+=(python3-venv)
fi
if [ ${#need_apt[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ]; then
        echo "bootstrap: installing Debian packages: ${need_apt[*]}"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}"
    else
        echo "bootstrap: missing ${need_apt[*]}; install them (as root: apt-get install ${need_apt[*]})" >&2
        exit 1
    fi
fi

# clang with the AddressSanitizer/UndefinedBehaviorSanitizer and libFuzzer runtimes, for the
# sanitizer and fuzz tests (tests/test_sanitizers.py); Debian ships the runtimes in
# libclang-rt-<major>-dev. Installed when root and missing; otherwise those tests say so.
clang_ok() {
    command -v clang >/dev/null 2>&1 || return 1
    local d; d=$(mktemp -d)
    printf '#include <stddef.h>\n#include <stdint.h>\nint LLVMFuzzerTestOneInput(const uint8_t *d, size_t n) { (void)d; (void)n; return 0; }\n' > "$d/p.c"
    clang -fsanitize=fuzzer,address,undefined "$d/p.c" -o "$d/p" >/dev/null 2>&1
    local rc=$?
    rm -rf "$d"
    return $rc
}
if ! clang_ok; then
    if [ "$(id -u)" = 0 ]; then
        echo "bootstrap: installing Debian's clang and its sanitizer/libFuzzer runtimes"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq clang
        major=$(clang --version | sed -n 's/.*clang version \([0-9]*\).*/\1/p' | head -1)
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "libclang-rt-${major}-dev" \
            || DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "libclang-common-${major}-dev"
        clang_ok || echo "bootstrap: clang still cannot build a fuzzer; the sanitizer tests will fail" >&2
    else
        echo "bootstrap: clang with libFuzzer missing (as root: apt-get install clang libclang-rt-<version>-dev);" \
             "the sanitizer and fuzz tests need it" >&2
    fi
fi

# clang-format, for the style test of the hand-written C (.clang-format)
if ! command -v clang-format >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ]; then
        echo "bootstrap: installing Debian's clang-format"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq clang-format
    else
        echo "bootstrap: clang-format missing (as root: apt-get install clang-format); the style test needs it" >&2
    fi
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    echo "bootstrap: creating .venv"
    "$PY" -m venv .venv
fi
stamp=.venv/.dopus-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "bootstrap: installing dopus-codegen and its dependencies into .venv"
    .venv/bin/python -m pip install -q --upgrade pip "setuptools>=77" wheel
    .venv/bin/python -m pip install -q -e ".[dev]"
    touch "$stamp"
fi
