#!/usr/bin/env bash
# Regression guard for changes to a hot path (issue 25): runs our benchmarks (no peer programs)
# on small, steady cases, takes the median of N runs of each and compares it with the figure
# recorded for this machine in bench/guard.tsv. Exit status 1 when a case got slower than its
# record by more than TOLERANCE percent; 0 otherwise. Run it before merging a change to the
# force kernels, the neighbour lists, the integration, the FEM assembly/solve or the transport,
# and after an accepted speed-up record the new figures (--record) in the same commit.
#
#   bench/guard.sh                 # build the benches (cargo bench --no-run), measure, compare
#   bench/guard.sh --record        # measure and write the figures as the new record
#   N=5 TOLERANCE=5 GUARD_CASES="dense pour" bench/guard.sh
#
# Cases (lower is better; each ~10-60 s per run after a one-time settling that is cached):
#   dense      REFERENCE D dense bed, 1 nm jitter, settled (cached), 2,000 steps: ns per particle-step
#   pour       polydisperse pour, 5,000 spheres (bench/liggghts/pour_gen.py 5000 1), 50,000
#              steps of fall, impacts and settling: ns per particle-step
#   polyhedra  2,000 dilated polyhedra (30 triangles) settled (cached), 500 steps: core-µs per
#              particle-step
#   superquadrics  2,000 superquadrics of Wellmann's sand settled (cached), 2,000 steps on one
#              thread (on two the runs spread by ±20 % on the VM): core-µs per particle-step
#   fem10      static beam, hex8 10 mm (36,663 dof): build + assembly + factorise + solve, s
#   transport  10k-node kinematics round trip on loopback: median µs
#   window     the coupling overhead per window of scenes/sheet-ci.toml (7,000 windows of a
#              predictive DEM-FEM run, release binaries, ~30 s): (wall − critical path) / windows, µs
#
# Environment: N [3] runs per case; TOLERANCE [10] percent; THREADS [2] cores per benchmark;
# GUARD_CASES ["dense pour polyhedra superquadrics fem10 transport window"]; GUARD_FILE [bench/guard.tsv];
# GUARD_CACHE [~/.cache/cosim-guard] (settled states, the pour's start file, logs);
# GUARD_NO_BUILD [0] (1: use the newest bench executables found, see bench/lib.sh).
#
# The records are figures of one machine: on another machine record first (--record), then
# guard. The machine must be quiet: a figure taken beside a build or a long run means nothing
# (the script prints the load average before each case).
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(dirname "$HERE")
N=${N:-3}
TOLERANCE=${TOLERANCE:-10}
THREADS=${THREADS:-2}
GUARD_CASES=${GUARD_CASES:-"dense pour polyhedra superquadrics fem10 transport window"}
GUARD_FILE=${GUARD_FILE:-$HERE/guard.tsv}
CACHE=${GUARD_CACHE:-$HOME/.cache/cosim-guard}
RECORD=0

log() { printf '%s\n' "$*" >&2; }
die() { log "guard.sh: $*"; exit 2; }

for a in "$@"; do
    case $a in
    --record) RECORD=1 ;;
    -h | --help) awk 'NR > 1 && /^#/ {sub(/^# ?/, ""); print; next} NR > 1 {exit}' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) die "unknown argument '$a' (--record, --help)" ;;
    esac
done
[[ $N =~ ^[1-9][0-9]*$ ]] || die "N must be a positive integer (got '$N')"
[[ $TOLERANCE =~ ^[0-9]+([.][0-9]+)?$ ]] || die "TOLERANCE must be a number of percent (got '$TOLERANCE')"
mkdir -p "$CACHE"
source "$HERE/lib.sh"

bench_of() { case $1 in dense) echo dense_bed ;; pour) echo pour ;; polyhedra) echo polyhedron_bed ;; superquadrics) echo superquadric_bed ;; fem10) echo static_beam ;; transport) echo transport ;; window) echo cosim ;; *) die "unknown case '$1' (dense pour polyhedra superquadrics fem10 transport window)" ;; esac; }
unit_of() { case $1 in dense | pour) echo ns/particle-step ;; polyhedra | superquadrics) echo core-µs/particle-step ;; fem10) echo s ;; transport | window) echo µs ;; esac; }

# one run of a case: prints its figure (stdout), log in $CACHE/<case>.<run>.log
measure() { # case run
    local c=$1 log="$CACHE/$1.$2.log" bin
    if [[ $c == window ]]; then bin=$(find_release_bin cosim); else bin=$(find_bench "$(bench_of "$c")"); fi
    [[ -n $bin ]] || die "no $(bench_of "$c") bench executable; run without GUARD_NO_BUILD"
    case $c in
    dense)
        DENSE_BED_THREADS=$THREADS DENSE_BED_JITTER=1e-9 DENSE_BED_STEPS=2000 DENSE_BED_SCALING_MAX=0 \
            DENSE_BED_CACHE="$CACHE/dense_bed.snap" "$bin" >"$log" 2>&1 || die "dense bed failed: $log"
        sed -n 's/^timed .* \([0-9.]*\) ns per particle-step.*/\1/p' "$log"
        ;;
    pour)
        [[ -s $CACHE/pour5000.data ]] || python3 "$HERE/liggghts/pour_gen.py" 5000 1 >"$CACHE/pour5000.data"
        POUR_THREADS=$THREADS POUR_STEPS=50000 POUR_DATA="$CACHE/pour5000.data" "$bin" >"$log" 2>&1 ||
            die "pour failed: $log"
        sed -n 's/^timed .* \([0-9.]*\) ns per particle-step.*/\1/p' "$log"
        ;;
    polyhedra)
        PB_THREADS=$THREADS PB_COUNT=2000 PB_STEPS=500 PB_NARROW=0 PB_CACHE="$CACHE/poly2000.snap" \
            "$bin" >"$log" 2>&1 || die "polyhedron bed failed: $log"
        sed -n 's/.* timed steps: .* = \([0-9.]*\) core-µs per particle-step.*/\1/p' "$log"
        ;;
    superquadrics)
        SQ_BED_THREADS=1 SQ_BED_COUNT=2000 SQ_BED_STEPS=2000 SQ_PROTOCOL_PAIRS=0 SQ_BED_NARROW=0 \
            SQ_BED_CACHE="$CACHE/sq2000.snap" "$bin" >"$log" 2>&1 || die "superquadric bed failed: $log"
        sed -n 's/.* timed steps: .* = \([0-9.]*\) core-µs per particle-step.*/\1/p' "$log"
        ;;
    fem10)
        RAYON_NUM_THREADS=$THREADS "$bin" 10 >"$log" 2>&1 || die "static beam failed: $log"
        grep -m1 '^static hex8 10 mm:' "$log" | sed -n 's/.* total \([0-9.]*\) s,.*/\1/p'
        ;;
    transport)
        COSIM_BENCH_ROUNDS=200 "$bin" >"$log" 2>&1 || die "transport failed: $log"
        awk '$1 == 10000 && NF >= 6 {print $3}' "$log"
        ;;
    window)
        "$bin" run "$ROOT/scenes/sheet-ci.toml" --out "$CACHE/window" --overwrite --no-progress \
            >"$log" 2>&1 || die "sheet-ci failed: $log"
        python3 -c 'import json, sys
s = json.load(open(sys.argv[1]))
print("%.1f" % (1e6 * s["timing"]["coupling_overhead_s"] / s["windows_done"]))' "$CACHE/window/summary.json"
        ;;
    esac
}

if [[ ${GUARD_NO_BUILD:-0} != 1 ]]; then
    command -v cargo >/dev/null || die "cargo is needed to build the benches (or GUARD_NO_BUILD=1)"
    for c in $GUARD_CASES; do
        b=$(bench_of "$c")
        log "building $b"
        build_bench "$b" >/dev/null 2>"$CACHE/build.$b.log" || die "building $b failed: $CACHE/build.$b.log"
    done
fi

commit=$(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null || echo '?')
dirty=$(git -C "$ROOT" status --porcelain --untracked-files=no 2>/dev/null | head -1)
[[ -n $dirty ]] && commit="$commit+changes"
declare -A MEDIAN RUNS
for c in $GUARD_CASES; do
    vals=()
    for ((i = 1; i <= N; i++)); do
        log "[$c $i/$N] $(date +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
        v=$(measure "$c" "$i")
        [[ -n $v ]] || die "no figure in $CACHE/$c.$i.log"
        vals+=("$v")
    done
    RUNS[$c]=$(IFS=,; echo "${vals[*]}")
    MEDIAN[$c]=$(printf '%s\n' "${vals[@]}" | median)
done

# the record: case, figure, unit, date, commit, runs
recorded() { [[ -f $GUARD_FILE ]] && awk -F'\t' -v c="$1" '$1 == c {v=$2} END{print v}' "$GUARD_FILE" || true; }
recorded_at() { [[ -f $GUARD_FILE ]] && awk -F'\t' -v c="$1" '$1 == c {v=$4 " " $5} END{print v}' "$GUARD_FILE" || true; }

echo "## Regression guard, $(date -u '+%Y-%m-%d %H:%M UTC'), $commit, $THREADS threads, $N runs, tolerance $TOLERANCE %"
echo
echo "| case | unit | median now | runs | record | recorded | change |"
echo "|---|---|---|---|---|---|---|"
fail=0
for c in $GUARD_CASES; do
    r=$(recorded "$c")
    if [[ -z $r ]]; then
        change="no record"
    else
        change=$(awk -v a="${MEDIAN[$c]}" -v b="$r" -v t="$TOLERANCE" 'BEGIN{
            p = (a / b - 1) * 100; s = sprintf("%+.1f %%", p)
            if (p > t) s = s " **slower**"; else if (p < -t) s = s " faster"; print s}')
        [[ $change == *slower* ]] && fail=1
    fi
    echo "| $c | $(unit_of "$c") | ${MEDIAN[$c]} | ${RUNS[$c]} | ${r:-—} | $(recorded_at "$c") | $change |"
done
echo

if ((RECORD)); then
    tmp=$(mktemp)
    { echo -e "# case\tfigure\tunit\tdate\tcommit\truns\t(bench/guard.sh --record; lower is better)"
        [[ -f $GUARD_FILE ]] && awk -F'\t' -v cases=" $GUARD_CASES " '$1 !~ /^#/ && index(cases, " " $1 " ") == 0' "$GUARD_FILE"
        for c in $GUARD_CASES; do
            echo -e "$c\t${MEDIAN[$c]}\t$(unit_of "$c")\t$(date -u +%Y-%m-%d)\t$commit\t${RUNS[$c]}"
        done
    } >"$tmp"
    mv "$tmp" "$GUARD_FILE"
    echo "recorded in $GUARD_FILE"
    exit 0
fi
if ((fail)); then
    echo "**A case is slower than its record by more than $TOLERANCE %.** Measure again on a quiet machine; if it holds, find the cause before merging."
    exit 1
fi
echo "No case slower than its record by more than $TOLERANCE %."
