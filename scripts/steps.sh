# Sourced by scripts/test.sh and scripts/lint.sh (not run on its own): what both set up.
# - CI=true: no incremental compilation (a fresh clone builds everything once; its
#   caches would only cost time and disk). A developer's repeated local runs keep them.
# - `step NAME`: prints `== NAME`, and the time the step before it took; on exit, the
#   last step's time and the total (CONTRIBUTING.md quotes these).
# - `target`: cargo's target directory.
[ -z "${CI:-}" ] || export CARGO_INCREMENTAL=0

step_name="" step_start=$SECONDS
step() {
    [ -z "$step_name" ] || printf '== %s: %d s\n' "$step_name" $((SECONDS - step_start))
    step_name="$*" step_start=$SECONDS
    printf '\n== %s\n' "$*"
}
finish() {
    [ -z "$step_name" ] || printf "== %s: %d s (total %d s)\n" "$step_name" $((SECONDS - step_start)) $SECONDS
}
trap finish EXIT
target=$(cargo metadata --format-version 1 --no-deps --locked | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
