#!/usr/bin/env bash
# The C interface end to end, with the system compilers: builds libqtvpr (shared and
# static, dev profile), compiles the C example against include/qtvpr.h and links it
# once against each, compiles the C++ example and a file that includes the header as
# C89 (-pedantic), and checks that their output equals
# `qtvpr-cli stream --format jsonl` on real data in both matching modes (the embedded
# VPR-Bench Corridor always; Nordland HOG and VPR-Bench SPEDTest when ../shared/data is
# there). Then runs a forked child (examples/c/fork.c: its decisions must equal the
# parent's), the C error-path test, the hostile-file test (examples/c/hostile.c: a FIFO,
# bit flips, bombs; under `ulimit -v 1000000`), and runs the error-path and hostile
# tests and one stream under valgrind (no leak, no invalid access). That
# include/qtvpr.h is current is checked by
# `cargo test` (crates/qtvpr-capi/tests/header.rs).
#
# Called by scripts/test.sh; runs alone from a fresh clone too. Needs cc, c++ and
# python3; the valgrind step says it is skipped when valgrind is missing (test.sh's
# set-up installs it with apt-get when running as root).
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n== %s\n' "$*"; }
read -r target version < <(cargo metadata --format-version 1 --no-deps --locked | python3 -c '
import json, sys
m = json.load(sys.stdin)
print(m["target_directory"], next(p["version"] for p in m["packages"] if p["name"] == "qtvpr-capi"))')
[ -n "${version:-}" ] || { echo "cargo metadata failed" >&2; exit 1; }
work="$target/capi-test"
rm -rf "$work"
mkdir -p "$work/lib" "$work/tmp"

step "build libqtvpr and qtvpr-cli"
cargo build --locked -p qtvpr-capi -p qtvpr-cli
# Copies, so that what is tested is what was just built even if the target directory
# is shared.
cp "$target/debug/libqtvpr.so" "$target/debug/libqtvpr.a" "$work/lib/"
cp "$target/debug/qtvpr-cli" "$work/"
cli="$work/qtvpr-cli"

step "compile the examples (shared and static library)"
cflags=(-std=c99 -Wall -Wextra -Wpedantic -Werror -Iinclude -Iexamples/c)
shared=(-L"$work/lib" -lqtvpr -Wl,-rpath,"$work/lib")
static=("$work/lib/libqtvpr.a" -lpthread -ldl -lm)
cc "${cflags[@]}" examples/c/stream.c "${shared[@]}" -o "$work/stream"
cc "${cflags[@]}" examples/c/stream.c "${static[@]}" -o "$work/stream-static"
c++ -std=c++17 -Wall -Wextra -Wpedantic -Werror -Iinclude -Iexamples/c examples/c/stream.cpp "${shared[@]}" \
    -o "$work/stream-cpp"
cc "${cflags[@]}" -pthread examples/c/errors.c "${shared[@]}" -lm -o "$work/errors"
cc "${cflags[@]}" examples/c/minimal.c "${shared[@]}" -o "$work/minimal"
cc "${cflags[@]}" examples/c/fork.c "${shared[@]}" -o "$work/fork"
cc "${cflags[@]}" examples/c/hostile.c "${shared[@]}" -o "$work/hostile"
if ldd "$work/stream-static" | grep -q libqtvpr; then
    echo "stream-static links libqtvpr.so" >&2
    exit 1
fi

step "the header alone is C89: -std=c89 -pedantic -Werror"
printf '#include "qtvpr.h"\nint main(void) { return qtvpr_version() == 0; }\n' > "$work/c89.c"
cc -std=c89 -pedantic -Wall -Wextra -Werror -Iinclude "$work/c89.c" "${shared[@]}" -o "$work/c89"
"$work/c89"

# stream NAME CAL_S CAL_GT_ARGS DEPLOY_S WINDOW: calibrate in both matchings, then
# check that every example prints what `qtvpr-cli stream` prints.
check_stream() {
    local name=$1 cal_s=$2 gt=$3 deploy=$4 window=$5 matching
    # single, multi, single with the margin gate (its decisions carry margin and gate),
    # with the sequence gate (consistency and consistency_level), and with both gates on
    # a calibration of sequence length 11 (each query decided on its causal
    # sequence-matched column).
    for matching in single multi margin sequence sequence11; do
        local cal="$work/$name-$matching.npz" want="$work/$name-$matching.jsonl" mode=(--matching "$matching")
        [ "$matching" = margin ] && mode=(--matching single --gate margin)
        [ "$matching" = sequence ] && mode=(--matching single --gate sequence)
        [ "$matching" = sequence11 ] && mode=(--matching single --gate margin,sequence --sequence 11)
        # shellcheck disable=SC2086 # gt is the ground-truth arguments
        "$cli" calibrate --cal "$cal_s" $gt "${mode[@]}" --window "$window" --output "$cal"
        "$cli" --quiet stream --calibration "$cal" --val "$deploy" --min-window 2 > "$want"
        for example in stream stream-static stream-cpp; do
            "$work/$example" "$cal" "$deploy" 0 0 0 2 > "$work/$name-$matching-$example.jsonl"
            python3 scripts/capi_check.py compare "$want" "$work/$name-$matching-$example.jsonl"
        done
        if [ "$matching" = margin ] && ! grep -q '"margin":.*"gate":' "$want"; then
            echo "$want: gated decisions without margin and gate" >&2
            exit 1
        fi
        if [[ "$matching" = sequence* ]] && ! grep -q '"consistency":.*"consistency_level":0.8}' "$want"; then
            echo "$want: decisions with the sequence gate without consistency and its level" >&2
            exit 1
        fi
    done
}

step "examples reproduce qtvpr-cli stream: VPR-Bench Corridor, AMOSNet (float64, embedded)"
check_stream corridor data/corridor/cal_S.npy "--cal-gt data/corridor/cal_GT.npy" data/corridor/deploy_S.npy 20

shared_data=../shared/data
if [ -d "$shared_data" ]; then
    step "examples reproduce qtvpr-cli stream: VPR-Bench SPEDTest, NetVLAD (float32)"
    python3 scripts/capi_check.py split "$shared_data/vprbench-spedtest/S_NetVLAD.npy" 60 \
        "$work/sped-cal.npy" "$work/sped-deploy.npy"
    python3 scripts/capi_check.py split "$shared_data/vprbench-spedtest/GT.npy" 60 \
        "$work/sped-cal-gt.npy" "$work/sped-deploy-gt.npy"
    check_stream sped "$work/sped-cal.npy" "--cal-gt $work/sped-cal-gt.npy" "$work/sped-deploy.npy" 50

    step "examples reproduce qtvpr-cli stream: Nordland HOG, winter vs summer (float32, 3576 x 3576)"
    "$cli" similarity --db "$shared_data/nordland-hog/db_winter.npy" \
        --queries "$shared_data/nordland-hog/query_summer.npy" --output "$work/nordland.npy"
    python3 scripts/capi_check.py split "$work/nordland.npy" 357 "$work/nordland-cal.npy" "$work/nordland-deploy.npy"
    check_stream nordland "$work/nordland-cal.npy" "--cal-gt-tolerance 1" "$work/nordland-deploy.npy" 100
else
    echo "(no $shared_data: Nordland and SPEDTest skipped)"
fi

step "the README's example"
python3 scripts/capi_check.py raw data/corridor/deploy_S.npy "$work/corridor-deploy.f32"
"$work/minimal" "$work/corridor-single.npz" < "$work/corridor-deploy.f32" > "$work/minimal.txt"
[ "$(wc -l < "$work/minimal.txt")" = 100 ] || { echo "minimal: expected 100 decisions" >&2; exit 1; }
head -n 2 "$work/minimal.txt"
if "$work/minimal" "$work/missing.npz" < /dev/null 2> "$work/minimal.err"; then
    echo "minimal: a missing calibration file is not an error" >&2
    exit 1
fi
grep -q "missing.npz" "$work/minimal.err"
cat "$work/minimal.err"

step "a process that forks after using the library: the child's decisions equal the parent's"
"$work/fork" "$work/corridor-single.npz" data/corridor/deploy_S.npy
"$work/fork" "$work/corridor-multi.npz" data/corridor/deploy_S.npy

step "pkg-config: the library installed under a prefix, as the README says"
if command -v pkg-config > /dev/null; then
    prefix="$work/prefix"
    mkdir -p "$prefix/include" "$prefix/lib/pkgconfig"
    cp include/qtvpr.h "$prefix/include/"
    cp "$work/lib/libqtvpr.so" "$work/lib/libqtvpr.a" "$prefix/lib/"
    for pc in qtvpr qtvpr-static; do
        sed -e "s|@PREFIX@|$prefix|" -e "s|@VERSION@|$version|" "crates/qtvpr-capi/$pc.pc.in" > "$prefix/lib/pkgconfig/$pc.pc"
    done
    export PKG_CONFIG_PATH="$prefix/lib/pkgconfig"
    [ "$(pkg-config --modversion qtvpr)" = "$version" ]
    # Linked with pkg-config's flags alone: the shared one runs with no LD_LIBRARY_PATH
    # (its run-time path is in qtvpr.pc), the static one has no libqtvpr.so at all.
    # shellcheck disable=SC2046 # pkg-config's flags are words
    cc -std=c99 examples/c/minimal.c $(pkg-config --cflags --libs qtvpr) -o "$work/minimal-pc"
    # shellcheck disable=SC2046
    cc -std=c99 examples/c/minimal.c $(pkg-config --cflags --libs qtvpr-static) -o "$work/minimal-pc-static"
    if ldd "$work/minimal-pc-static" | grep -q libqtvpr; then
        echo "minimal-pc-static links libqtvpr.so" >&2
        exit 1
    fi
    for app in minimal-pc minimal-pc-static; do
        env -u LD_LIBRARY_PATH "$work/$app" "$work/corridor-single.npz" < "$work/corridor-deploy.f32" | cmp - "$work/minimal.txt"
    done
    echo "cc app.c \$(pkg-config --cflags --libs qtvpr): $(pkg-config --cflags --libs qtvpr)"
else
    echo "(no pkg-config: skipped)"
fi

step "error paths from C"
errors=("$work/errors" "$work/corridor-single.npz" 111 "$work/tmp" "$work/corridor-multi.npz")
"${errors[@]}"

step "hostile calibration files from C, under ulimit -v 1000000"
# A small calibration to flip byte by byte, it with a bad CRC in s, two bombs (a few kB
# of bzip2 expanding to 1 GiB, and 40 MB deflated whose shape disagrees with gt), the
# hostile set of tests/hostile_npz.py, and a valid calibration too large for the cap.
python3 scripts/capi_check.py small "$work/small-s.npy" "$work/small-gt.npy"
"$cli" calibrate --cal "$work/small-s.npy" --cal-gt "$work/small-gt.npy" --window 4 --output "$work/small.npz"
python3 scripts/capi_check.py flip "$work/small.npz" s "$work/crc.npz"
python3 scripts/capi_check.py bomb "$work/bomb-bzip2.npz" bzip2
python3 scripts/capi_check.py bomb "$work/bomb-deflate.npz" deflate
mkdir -p "$work/hostile-set"
python3 scripts/capi_check.py hostile-set "$work/small.npz" "$work/hostile-set"
hostile=("$work/hostile" "$work/tmp" "$work/small.npz" "$work/crc.npz" "$work/bomb-bzip2.npz" "$work/bomb-deflate.npz"
    "$work/hostile-set/manifest.tsv" "$work/hostile-set/big.npz")
# In a subshell, so that the cap ends with it; a hang is ended by the test's alarm().
(ulimit -v 1000000 && exec "${hostile[@]}")

step "valgrind: the error test, the hostile-file test and a stream"
# scripts/test.sh's set-up installs it (apt, as root); this script installs nothing.
if ! command -v valgrind > /dev/null; then
    echo "skipped: valgrind is not installed (apt-get install valgrind, or run scripts/test.sh as root)"
    exit 0
fi
# examples/c/valgrind.supp says what it suppresses and why (rayon's threads at exit).
vg=(valgrind --quiet --error-exitcode=1 --leak-check=full --errors-for-leak-kinds=definite,indirect,possible
    --suppressions=examples/c/valgrind.supp)
"${vg[@]}" "${errors[@]}"
# About 35 s: every flipped file's and the hostile set's error paths, for leaks; not the
# file too large for the cap, which valgrind does not bind.
"${vg[@]}" "${hostile[@]:0:7}"
"${vg[@]}" "$work/stream" "$work/corridor-multi.npz" data/corridor/deploy_S.npy 0 0 0 2 > "$work/valgrind.jsonl"
python3 scripts/capi_check.py compare "$work/corridor-multi.jsonl" "$work/valgrind.jsonl"
