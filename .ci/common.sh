# Helpers shared by .ci/run and .ci/oclgrind_step (sourced, not run).
run() { echo "+ $*"; "$@"; }
run_pytest() {  # run_pytest ARGS...: pytest in the current venv; exit 5 (nothing collected) is a failure
    local rc=0
    echo "+ python -m pytest $*"
    python -m pytest "$@" || rc=$?
    if [ "$rc" -eq 5 ]; then
        echo "pytest collected no tests (exit 5): that is a CI failure" >&2
    elif [ "$rc" -ne 0 ]; then
        echo "pytest failed (exit $rc)" >&2
    fi
    return "$rc"
}
