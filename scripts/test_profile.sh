# Sourced, not run: the release profile the tests build in (scripts/test.sh),
# which .ci/run also gives the demo and the benchmarks so that one build
# serves all. Release with this repository's debug assertions and overflow
# checks on (the root Cargo.toml keeps the dependencies' off), without fat
# LTO, in 16 codegen units and with line tables only: the code the tests
# check, compiled once, where a debug build of the tests plus a release
# build for the 3x3 design's took 1.5x as long in CI. Floating-point results
# do not depend on the optimisation level. The caller's own
# CARGO_PROFILE_RELEASE_* values win.
: "${CARGO_PROFILE_RELEASE_LTO:=false}" "${CARGO_PROFILE_RELEASE_CODEGEN_UNITS:=16}"
: "${CARGO_PROFILE_RELEASE_DEBUG:=line-tables-only}"
: "${CARGO_PROFILE_RELEASE_DEBUG_ASSERTIONS:=true}" "${CARGO_PROFILE_RELEASE_OVERFLOW_CHECKS:=true}"
export CARGO_PROFILE_RELEASE_LTO CARGO_PROFILE_RELEASE_CODEGEN_UNITS CARGO_PROFILE_RELEASE_DEBUG \
    CARGO_PROFILE_RELEASE_DEBUG_ASSERTIONS CARGO_PROFILE_RELEASE_OVERFLOW_CHECKS
