#!/usr/bin/env bash
# Side-by-side benchmark of our solvers against the peer programs of REFERENCE D:
#   dem    dense bed, 24,696 spheres, 10,000 timed steps   ours: dense_bed bench  peer: LIGGGHTS
#   pour   polydisperse pour, 20,000 spheres d 3-5 mm, fall and settling, 50,000 timed steps
#                                                           ours: pour bench       peer: LIGGGHTS
#   hopper the same spheres flowing out of a hopper (STL) through a 30 mm outlet, 75,000 steps
#                                                           ours: pour bench       peer: LIGGGHTS
#   fem10  static beam, C3D8 at 10 mm (36,663 dof)         ours: static_beam      peer: CalculiX ccx
#   fem5   static beam, C3D8 at 5 mm (265,923 dof)         ours: static_beam      peer: CalculiX ccx
#   tet10  L-bracket meshed by Gmsh in C3D10 (unstructured, ~225,000 free dof; bench/gmsh/)
#                                                           ours: static_beam      peer: CalculiX ccx
#   transport  zenoh round trip (no peer program; REFERENCE D's figures are printed alongside)
#
# For each case the two programs alternate in one sitting (ABBA order: run 1 peer then ours,
# run 2 ours then peer, ...), N times each; the tables report medians, every single value, and
# the ratio peer/ours of the medians (> 1: ours is faster / smaller). A peer that is not
# installed is skipped with a message; ours is still measured.
#
# Environment (defaults in brackets):
#   N [3]               runs of each program per case
#   CASES ["dem pour hopper fem10 fem5 tet10 transport"]
#   THREADS [2]         cores given to each program: MPI ranks of LIGGGHTS, OMP threads of
#                       ccx (spooles), rayon threads of ours
#   DEM_SETTLE [40000]  settling steps before the timed ones (0.4 s), both codes
#   DEM_STEPS [10000]   timed DEM steps, both codes
#   DEM_JITTER [0]      random horizontal displacement (m) of the lattice sites, both codes; 0
#                       is REFERENCE D's exact lattice, which LIGGGHTS keeps as 441 static
#                       columns while ours breaks that symmetry by itself, later (README.md);
#                       1e-9 makes both settle into a random packing: like-for-like work
#   POUR_COUNT [20000] POUR_SEED [1]  spheres and seed of the pour's start (bench/liggghts/pour_gen.py)
#   POUR_STEPS [50000]  pour steps (0.4 s at 8 us), all timed, both codes
#   HOPPER_STEPS [75000] hopper steps (0.6 s), all timed, both codes (its start: the same
#                       count and seed, placed in the shaft above the funnel)
#   TET10_H [0.004]     Gmsh element size of the bracket (m): 0.004 gives 79,433 nodes
#   TRANSPORT_ROUNDS [200]
#   BENCH_WORK [mktemp] folder for the decks, logs and raw records (kept; printed at the end)
#   COSIM_TARGET_DIR    cargo target folder holding release/deps/{dense_bed,pour,static_beam,transport}-*
#                       (else $CARGO_TARGET_DIR, ~/.cache/cosim-target, <repo>/target; when no
#                       bench binary is found there it is built with `cargo bench --no-run`)
#   LIGGGHTS [liggghts] CCX [ccx] MPIRUN [mpirun] GMSH [gmsh] (tet10 needs Gmsh to mesh)
#
# Output: markdown on stdout; raw records (one line per run) in $BENCH_WORK/runs.tsv.
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(dirname "$HERE")
N=${N:-3}
CASES=${CASES:-"dem pour hopper fem10 fem5 tet10 transport"}
THREADS=${THREADS:-2}
DEM_SETTLE=${DEM_SETTLE:-40000}
DEM_STEPS=${DEM_STEPS:-10000}
DEM_JITTER=${DEM_JITTER:-0}
TRANSPORT_ROUNDS=${TRANSPORT_ROUNDS:-200}
POUR_COUNT=${POUR_COUNT:-20000}
POUR_SEED=${POUR_SEED:-1}
POUR_STEPS=${POUR_STEPS:-50000}
HOPPER_STEPS=${HOPPER_STEPS:-75000}
TET10_H=${TET10_H:-0.004}
GMSH=${GMSH:-gmsh}
LIGGGHTS=${LIGGGHTS:-liggghts}
CCX=${CCX:-ccx}
MPIRUN=${MPIRUN:-mpirun}
WORK=${BENCH_WORK:-$(mktemp -d "${TMPDIR:-/tmp}/cosim-bench.XXXXXX")}
mkdir -p "$WORK"
RUNS="$WORK/runs.tsv"
: >"$RUNS"

log() { printf '%s\n' "$*" >&2; }
die() { log "compare.sh: $*"; exit 1; }

[[ $N =~ ^[1-9][0-9]*$ ]] || die "N must be a positive integer (got '$N')"
TIME=/usr/bin/time
[[ -x $TIME ]] || die "GNU time is needed at $TIME (Debian: apt-get install time)"

# our bench executables (found or built): bench/lib.sh
source "$HERE/lib.sh"

# ---------------------------------------------------------------- measuring
# run_timed <dir> <tag> cmd... : runs cmd in <dir> under GNU time; stdout+stderr to <tag>.log,
# "wall user sys maxrss_kB" to <tag>.time
run_timed() {
    local dir=$1 tag=$2
    shift 2
    (cd "$dir" && "$TIME" -f '%e %U %S %M' -o "$tag.time" "$@" >"$tag.log" 2>&1) ||
        { log "FAILED: $* (see $dir/$tag.log)"; tail -5 "$dir/$tag.log" >&2; return 1; }
}

# record <case> <prog> <run> <time_s> <wall_s> <cpu_s> <rss_MB> <answers...>
record() { local IFS=$'\t'; echo "$*" >>"$RUNS"; }

timefile() { read -r W U S M <"$1"; CPU=$(awk -v u="$U" -v s="$S" 'BEGIN{printf "%.2f", u+s}'); }

# ---------------------------------------------------------------- LIGGGHTS runs
# the LIGGGHTS command (one rank, or THREADS ranks under mpirun), each rank under GNU time
# (screen output to /dev/null, not `-screen none`: LIGGGHTS 3.8 segfaults reading a mesh file
# without a screen)
liggghts_cmd() { # dir tag args...
    local d=$1 tag=$2
    shift 2
    if ((THREADS > 1)); then
        run_timed "$d" "$tag" "$MPIRUN" --allow-run-as-root -np "$THREADS" \
            sh -c 'exec '"$TIME"' -f %M -o "$0.rss.$OMPI_COMM_WORLD_RANK" '"$LIGGGHTS"' "$@"' "$tag" \
            "$@" -log "$tag.lammps" -echo none -screen /dev/null
    else
        run_timed "$d" "$tag" "$LIGGGHTS" "$@" -log "$tag.lammps" -echo none -screen /dev/null
    fi
    timefile "$d/$tag.time"
    RSS_KB=$M
    if ((THREADS > 1)); then RSS_KB=$(cat "$d/$tag".rss.* | awk '{s+=$1} END{print s}'); fi
}

# LIGGGHTS usable for case $1 (sets PEER_OK[$1]); Open MPI settings for containers and shared
# machines: no cross-memory attach; waiting ranks yield the core instead of spinning (a
# spinning rank steals time from its partner)
liggghts_check() {
    PEER_OK[$1]=1
    if ! have "$LIGGGHTS"; then
        log "SKIP peer: LIGGGHTS ('$LIGGGHTS') is not installed (Debian: apt-get install liggghts); measuring ours only"
        PEER_OK[$1]=0
    elif ((THREADS > 1)) && ! have "$MPIRUN"; then
        log "SKIP peer: $THREADS LIGGGHTS ranks need '$MPIRUN' (Debian: apt-get install openmpi-bin); measuring ours only"
        PEER_OK[$1]=0
    fi
    export OMPI_MCA_btl_vader_single_copy_mechanism=${OMPI_MCA_btl_vader_single_copy_mechanism:-none}
    export OMPI_MCA_mpi_yield_when_idle=${OMPI_MCA_mpi_yield_when_idle:-1}
}

# abba <case> <peer function> <our function> [args...]: N runs of each, alternating (run 1
# peer first, run 2 ours first, ...); the functions get the args and the run index
abba() {
    local c=$1 peer=$2 ours=$3 i
    shift 3
    for ((i = 1; i <= N; i++)); do
        log "[$c $i/$N] $(date +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
        if ((PEER_OK[$c] && i % 2 == 1)); then "$peer" "$@" "$i"; fi
        "$ours" "$@" "$i"
        if ((PEER_OK[$c] && i % 2 == 0)); then "$peer" "$@" "$i"; fi
    done
}

# ---------------------------------------------------------------- DEM: dense bed
dem_peer() { # run index
    local d="$WORK/dem" tag="liggghts.$1"
    liggghts_cmd "$d" "$tag" -in dense_bed.in -var settle "$DEM_SETTLE" -var steps "$DEM_STEPS" -var jitter "$DEM_JITTER"
    local t atoms ke contacts builds
    t=$(awk '/^Loop time of/{t=$4} END{print t}' "$d/$tag.lammps")
    builds=$(awk '/^Neighbor list builds/{b=$NF} END{print b}' "$d/$tag.lammps")
    # last thermo line: step atoms ke rke contacts zmax
    read -r _ atoms ke _ contacts _ < <(awk '$1 ~ /^[0-9]+$/ && NF == 6 {l=$0} END{print l}' "$d/$tag.lammps")
    [[ $atoms == 24696 ]] || log "WARNING: LIGGGHTS ran $atoms particles (expected 24696)"
    record dem liggghts "$1" "$t" "$W" "$CPU" "$((RSS_KB / 1024))" "particles=$atoms" "KE=$ke" "contacts=$contacts" "builds=$builds"
}

dem_ours() {
    local d="$WORK/dem" tag="ours.$1"
    run_timed "$d" "$tag" env DENSE_BED_THREADS="$THREADS" DENSE_BED_SETTLE="$DEM_SETTLE" \
        DENSE_BED_JITTER="$DEM_JITTER" DENSE_BED_STEPS="$DEM_STEPS" DENSE_BED_SCALING_MAX=0 "$DENSE_BED"
    timefile "$d/$tag.time"
    local t n ke contacts builds
    t=$(sed -n 's/^timed [0-9]* steps: \([0-9.]*\) s wall.*/\1/p' "$d/$tag.log")
    n=$(sed -n 's/^dense bed: \([0-9]*\) particles.*/\1/p' "$d/$tag.log")
    ke=$(sed -n 's/^timed .* KE \([-0-9.e+]*\) J.*/\1/p' "$d/$tag.log")
    contacts=$(sed -n 's/^timed .*; contacts \([0-9]*\),.*/\1/p' "$d/$tag.log")
    builds=$(sed -n 's/^timed .*, list builds \([0-9]*\),.*/\1/p' "$d/$tag.log")
    [[ -n $t ]] || die "no 'timed ... steps' line in $d/$tag.log"
    record dem ours "$1" "$t" "$W" "$CPU" "$((M / 1024))" "particles=$n" "KE=$ke" "contacts=$contacts" "builds=$builds"
}

# ---------------------------------------------------------------- DEM: polydisperse pour
# pour_peer / pour_ours <case> <run>: case pour (the box) or hopper (the flowing case)
pour_steps() { if [[ $1 == hopper ]]; then echo "$HOPPER_STEPS"; else echo "$POUR_STEPS"; fi; }

pour_peer() {
    local c=$1 d="$WORK/$1" tag="liggghts.$2"
    liggghts_cmd "$d" "$tag" -in "$c.in" -var steps "$(pour_steps "$c")" -var data "$c.data"
    local t atoms ke rke contacts zmax builds
    t=$(awk '/^Loop time of/{t=$4} END{print t}' "$d/$tag.lammps")
    builds=$(awk '/^Neighbor list builds/{b=$NF} END{print b}' "$d/$tag.lammps")
    read -r _ atoms ke rke contacts zmax < <(awk '$1 ~ /^[0-9]+$/ && NF == 6 {l=$0} END{print l}' "$d/$tag.lammps")
    # the hopper's spheres leave the domain below its outlet: LIGGGHTS deletes them ("lost")
    record "$c" liggghts "$2" "$t" "$W" "$CPU" "$((RSS_KB / 1024))" "particles=$atoms" \
        "KE=$(awk -v a="$ke" -v b="$rke" 'BEGIN{printf "%.3e", a + b}')" "contacts=$contacts" "builds=$builds" "zmax=$zmax" \
        "discharged=$((POUR_COUNT - atoms))"
}

pour_ours() {
    local c=$1 d="$WORK/$1" tag="ours.$2" geometry=box
    [[ $c == hopper ]] && geometry=hopper
    run_timed "$d" "$tag" env POUR_THREADS="$THREADS" POUR_STEPS="$(pour_steps "$c")" POUR_DATA="$c.data" \
        POUR_GEOMETRY=$geometry "$POUR"
    timefile "$d/$tag.time"
    local line t n gone
    line=$(grep -m1 '^timed ' "$d/$tag.log") || die "no 'timed ... steps' line in $d/$tag.log"
    t=$(sed -n 's/^timed [0-9]* steps: \([0-9.]*\) s wall.*/\1/p' <<<"$line")
    n=$(sed -n 's/^pour: \([0-9]*\) particles.*/\1/p' "$d/$tag.log")
    gone=$(sed -n 's/.*discharged \([0-9]*\).*/\1/p' <<<"$line")
    record "$c" ours "$2" "$t" "$W" "$CPU" "$((M / 1024))" "particles=$((n - gone))" \
        "KE=$(sed -n 's/.* KE \([-0-9.e+]*\) J.*/\1/p' <<<"$line")" \
        "contacts=$(sed -n 's/.*; contacts \([0-9]*\),.*/\1/p' <<<"$line")" \
        "builds=$(sed -n 's/.*, list builds \([0-9]*\),.*/\1/p' <<<"$line")" \
        "zmax=$(sed -n 's/.*highest centre \([0-9.]*\) m.*/\1/p' <<<"$line")" "discharged=$gone"
}

# ---------------------------------------------------------------- FEM: static beam
fem_prepare() { # h
    local d="$WORK/fem$1"
    mkdir -p "$d"
    cp "$HERE/ccx/beam_$1mm.inp" "$d/"
    [[ -s $d/mesh_$1mm.inp ]] || python3 "$HERE/ccx/beam_mesh.py" "$1" >"$d/mesh_$1mm.inp"
}

fem_peer() { # h run
    local d="$WORK/fem$1" tag="ccx.$2"
    rm -f "$d/beam_$1mm.dat"
    run_timed "$d" "$tag" env OMP_NUM_THREADS="$THREADS" CCX_NPROC_EQUATION_SOLVER="$THREADS" \
        "$CCX" -i "beam_$1mm"
    timefile "$d/$tag.time"
    local uz inner
    uz=$(awk '/displacements/{f=1; next} f && NF == 4 {print $4; exit}' "$d/beam_$1mm.dat")
    inner=$(awk '/Total CalculiX Time/{print $NF}' "$d/$tag.log")
    # the compared time is the process wall time (input reading, assembly, solve, stresses)
    record "fem$1" ccx "$2" "$W" "$W" "$CPU" "$((M / 1024))" "uz=$uz" "ccx_total=$inner"
}

# static_line <log> <prefix>: sets the caller's locals line (the static_beam line starting
# with prefix), t (build + solve, s) and hwm (VmHWM after the solve, MB)
static_line() {
    line=$(grep -m1 "^$2" "$1") || die "no '$2' line in $1"
    t=$(sed -n 's/.* total \([0-9.]*\) s,.*/\1/p' <<<"$line")
    hwm=$(sed -n 's/.*VmHWM \([0-9]*\) MB.*/\1/p' <<<"$line")
}

fem_ours() { # h run
    local d="$WORK/fem$1" tag="ours.$2" args=("$1")
    # the bench ends with a dynamic run at its largest size: give it the 10 mm mesh after 5 mm,
    # so the 5 mm process is not lengthened by a 5 mm dynamic solve (not timed below anyway)
    [[ $1 != 10 ]] && args+=(10)
    run_timed "$d" "$tag" env RAYON_NUM_THREADS="$THREADS" "$STATIC_BEAM" "${args[@]}"
    timefile "$d/$tag.time"
    local line t uz hwm
    static_line "$d/$tag.log" "static hex8 $1 mm:"
    uz=$(sed -n 's/.*midspan uz \([-0-9.e+]*\) m.*/\1/p' <<<"$line")
    # compared: build + assembly + factorise + solve as printed, and VmHWM right after the
    # solve (the process goes on with a re-solve and a dynamic run; its wall time is recorded)
    record "fem$1" ours "$2" "$t" "$W" "$CPU" "$hwm" "uz=$uz"
}

# ---------------------------------------------------------------- FEM: Gmsh tet10 bracket
tet10_prepare() {
    local d="$WORK/tet10"
    mkdir -p "$d"
    cp "$HERE/ccx/bracket.inp" "$HERE/gmsh/bracket.toml" "$d/"
    if [[ ! -s $d/bracket.msh ]]; then
        "$GMSH" -3 -order 2 -setnumber h "$TET10_H" -format msh41 "$HERE/gmsh/bracket.geo" \
            -o "$d/bracket.msh" >"$d/gmsh.log" 2>&1 || die "Gmsh failed (see $d/gmsh.log)"
    fi
    python3 "$HERE/gmsh/msh2inp.py" "$d/bracket.msh" 0.2 0.1 0.02 >"$d/mesh_bracket.inp"
}

tet10_peer() { # run
    local d="$WORK/tet10" tag="ccx.$1"
    rm -f "$d/bracket.dat"
    run_timed "$d" "$tag" env OMP_NUM_THREADS="$THREADS" CCX_NPROC_EQUATION_SOLVER="$THREADS" \
        "$CCX" -i bracket
    timefile "$d/$tag.time"
    local uz inner
    uz=$(awk '/displacements/{f=1; next} f && NF == 4 {print $4; exit}' "$d/bracket.dat")
    inner=$(awk '/Total CalculiX Time/{print $NF}' "$d/$tag.log")
    record tet10 ccx "$1" "$W" "$W" "$CPU" "$((M / 1024))" "uz=$uz" "ccx_total=$inner"
}

tet10_ours() { # run
    local d="$WORK/tet10" tag="ours.$1"
    run_timed "$d" "$tag" env RAYON_NUM_THREADS="$THREADS" "$STATIC_BEAM" bracket.toml
    timefile "$d/$tag.time"
    local line t uz hwm
    static_line "$d/$tag.log" "static bracket.toml:"
    uz=$(sed -n 's/.*corner u [-0-9.e+]* [-0-9.e+]* \([-0-9.e+]*\) m.*/\1/p' <<<"$line")
    record tet10 ours "$1" "$t" "$W" "$CPU" "$hwm" "uz=$uz"
}

# ---------------------------------------------------------------- transport (ours only)
transport_ours() {
    local d="$WORK/transport" tag="ours.$1"
    run_timed "$d" "$tag" env COSIM_BENCH_ROUNDS="$TRANSPORT_ROUNDS" "$TRANSPORT"
    timefile "$d/$tag.time"
    local a
    a=$(awk '$1 ~ /^[0-9]+$/ && NF >= 6 {printf "%s%s=%s", sep, $1, $3; sep=" "}' "$d/$tag.log")
    record transport ours "$1" "" "$W" "$CPU" "$((M / 1024))" $a
}

# ---------------------------------------------------------------- report helpers
col() { awk -F'\t' -v c="$1" -v p="$2" -v k="$3" '$1 == c && $2 == p {print $k}' "$RUNS"; }
all() { col "$@" | awk '{printf "%s%s", (NR > 1 ? ", " : ""), ($1 + 0 >= 100 ? sprintf("%.0f", $1) : sprintf("%.3g", $1))}'; }
answer() { # case prog key -> values of key=... in the answer fields
    awk -F'\t' -v c="$1" -v p="$2" -v k="$3" '$1 == c && $2 == p {for (i = 8; i <= NF; i++) if (index($i, k "=") == 1) print substr($i, length(k) + 2)}' "$RUNS"
}
ratio() { awk -v a="$1" -v b="$2" 'BEGIN{if (a == "" || b == "" || b + 0 == 0) print "n/a"; else printf "%.2f", a / b}'; }
fmt() { awk -v x="$1" 'BEGIN{if (x == "") print "—"; else if (x + 0 >= 100) printf "%.0f", x; else printf "%.3g", x}'; }

have() { command -v "$1" >/dev/null 2>&1; }

# ---------------------------------------------------------------- run
declare -A PEER_OK PEER_NAME
PEER_NAME[dem]=LIGGGHTS
PEER_NAME[pour]=LIGGGHTS
PEER_NAME[hopper]=LIGGGHTS
PEER_NAME[fem10]=CalculiX
PEER_NAME[fem5]=CalculiX
PEER_NAME[tet10]=CalculiX
UPTIME_BEFORE=$(uptime)

for c in $CASES; do
    case $c in
    dem)
        DENSE_BED=$(ours_bin dense_bed)
        mkdir -p "$WORK/dem"
        # a private copy: LIGGGHTS reads its input line by line while it runs
        cp "$HERE/liggghts/dense_bed.in" "$WORK/dem/"
        liggghts_check dem
        abba dem dem_peer dem_ours
        ;;
    pour | hopper)
        POUR=$(ours_bin pour)
        mkdir -p "$WORK/$c"
        cp "$HERE/liggghts/$c.in" "$WORK/$c/"
        if [[ $c == hopper ]]; then
            python3 "$HERE/liggghts/pour_gen.py" "$POUR_COUNT" "$POUR_SEED" 0.16 0.45 >"$WORK/$c/$c.data"
            python3 "$HERE/liggghts/hopper_stl.py" >"$WORK/$c/hopper.stl"
        else
            python3 "$HERE/liggghts/pour_gen.py" "$POUR_COUNT" "$POUR_SEED" >"$WORK/$c/$c.data"
        fi
        liggghts_check "$c"
        abba "$c" pour_peer pour_ours "$c"
        ;;
    fem10 | fem5)
        h=${c#fem}
        STATIC_BEAM=$(ours_bin static_beam)
        fem_prepare "$h"
        PEER_OK[$c]=1
        if ! have "$CCX"; then
            log "SKIP peer: CalculiX ('$CCX') is not installed (Debian: apt-get install calculix-ccx); measuring ours only"
            PEER_OK[$c]=0
        fi
        abba "$c" fem_peer fem_ours "$h"
        ;;
    tet10)
        if [[ ! -s $WORK/tet10/bracket.msh ]] && ! have "$GMSH"; then
            log "SKIP tet10: Gmsh ('$GMSH') meshes the bracket and is not installed (Debian: apt-get install gmsh)"
            CASES=$(sed 's/\btet10\b//' <<<"$CASES")
            continue
        fi
        STATIC_BEAM=$(ours_bin static_beam)
        tet10_prepare
        PEER_OK[$c]=1
        if ! have "$CCX"; then
            log "SKIP peer: CalculiX ('$CCX') is not installed (Debian: apt-get install calculix-ccx); measuring ours only"
            PEER_OK[$c]=0
        fi
        abba "$c" tet10_peer tet10_ours
        ;;
    transport)
        TRANSPORT=$(ours_bin transport)
        mkdir -p "$WORK/transport"
        PEER_OK[transport]=0
        abba transport true transport_ours
        ;;
    *) die "unknown case '$c' (dem pour hopper fem10 fem5 tet10 transport)" ;;
    esac
done
UPTIME_AFTER=$(uptime)

# ---------------------------------------------------------------- report
peer_prog() { case $1 in dem | pour | hopper) echo liggghts ;; *) echo ccx ;; esac; }
describe() {
    case $1 in
    dem) echo "DEM dense bed, 24,696 spheres, $DEM_STEPS steps after $DEM_SETTLE settling$( [[ $DEM_JITTER == 0 ]] || echo ", lattice jitter $DEM_JITTER m (both)")" ;;
    pour) echo "DEM polydisperse pour, $POUR_COUNT spheres d 3–5 mm (seed $POUR_SEED), $POUR_STEPS steps of fall and settling" ;;
    hopper) echo "DEM hopper discharge, $POUR_COUNT spheres d 3–5 mm (seed $POUR_SEED), 30 mm outlet, $HOPPER_STEPS steps" ;;
    fem10) echo "FEM static beam C3D8 10 mm (36,663 dof)" ;;
    fem5) echo "FEM static beam C3D8 5 mm (265,923 dof)" ;;
    tet10) echo "FEM static L-bracket, Gmsh C3D10, h = $TET10_H m ($(sed -n 's/.*: \([0-9]*\) nodes.*/\1/p' "$WORK/tet10/mesh_bracket.inp" | head -1) nodes)" ;;
    esac
}

echo "## Benchmark: ours vs peer, $(date -u '+%Y-%m-%d %H:%M UTC')"
echo
echo "- repo $(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null || echo '?'), $N runs per program per case, ABBA order, $THREADS cores per program ($(nproc) online)"
echo "- load before: \`${UPTIME_BEFORE## }\`"
echo "- load after:  \`${UPTIME_AFTER## }\`"
for v in DENSE_BED POUR STATIC_BEAM TRANSPORT; do
    [[ -n ${!v:-} ]] && echo "- ours: \`${!v}\` (built $(date -u -r "${!v}" '+%Y-%m-%d %H:%M UTC'))"
done
have "$LIGGGHTS" && echo "- LIGGGHTS: \`$(command -v "$LIGGGHTS")\` $(dpkg-query -W -f='${Version}' liggghts 2>/dev/null || true)"
have "$CCX" && echo "- CalculiX: \`$(command -v "$CCX")\` $(dpkg-query -W -f='${Version}' calculix-ccx 2>/dev/null || true)"
echo
echo "Time: DEM = the $DEM_STEPS timed steps (LIGGGHTS \"Loop time\", ours \"timed ... s wall\"); pour = all its steps;"
echo "FEM = ccx process wall time vs ours build + assembly + factorise + solve. Peak RSS: LIGGGHTS"
echo "summed over its ranks; ccx and ours DEM the process maximum; ours FEM VmHWM after the solve."
echo "Ratio = peer median / ours median (> 1: ours is faster or smaller)."
echo
echo "| case | peer | peer time s (median) | ours time s (median) | time ratio | peer runs | ours runs | peer RSS MB | ours RSS MB | RSS ratio | peer wall / CPU s | ours wall / CPU s |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
for c in $CASES; do
    [[ $c == transport ]] && continue
    p=$(peer_prog "$c")
    pt=$(col "$c" "$p" 4 | median); ot=$(col "$c" ours 4 | median)
    pr=$(col "$c" "$p" 7 | median); orr=$(col "$c" ours 7 | median)
    pw=$(col "$c" "$p" 5 | median); ow=$(col "$c" ours 5 | median)
    pc=$(col "$c" "$p" 6 | median); oc=$(col "$c" ours 6 | median)
    pname=${PEER_NAME[$c]}
    ((PEER_OK[$c])) || pname="$pname (not installed: skipped)"
    echo "| $(describe "$c") | $pname | $(fmt "$pt") | $(fmt "$ot") | $(ratio "$pt" "$ot") | $(all "$c" "$p" 4) | $(all "$c" ours 4) | $(fmt "$pr") | $(fmt "$orr") | $(ratio "$pr" "$orr") | $(fmt "$pw") / $(fmt "$pc") | $(fmt "$ow") / $(fmt "$oc") |"
done
echo
echo "Answers (last value of each run):"
echo
echo "| case | quantity | peer | ours |"
echo "|---|---|---|---|"
for c in $CASES; do
    p=$(peer_prog "$c")
    case $c in
    dem)
        for k in particles KE contacts builds; do
            echo "| dem | $k$( [[ $k == builds ]] && echo ' (neighbour lists, timed steps)') | $(answer dem "$p" $k | paste -sd, - | sed 's/,/, /g') | $(answer dem ours $k | paste -sd, - | sed 's/,/, /g') |"
        done
        ;;
    pour | hopper)
        for k in particles KE contacts builds zmax discharged; do
            echo "| $c | $k$( [[ $k == zmax ]] && echo ' (highest centre, m)') | $(answer "$c" "$p" $k | paste -sd, - | sed 's/,/, /g') | $(answer "$c" ours $k | paste -sd, - | sed 's/,/, /g') |"
        done
        ;;
    tet10)
        echo "| $c | corner uz (0.2, 0.1, 0.02), m | $(answer "$c" "$p" uz | sort -u | paste -sd, -) | $(answer "$c" ours uz | sort -u | paste -sd, -) |"
        ;;
    fem*)
        echo "| $c | mid-span uz, m | $(answer "$c" "$p" uz | sort -u | paste -sd, -) | $(answer "$c" ours uz | sort -u | paste -sd, -) |"
        ;;
    esac
done
if [[ " $CASES " == *" transport "* ]]; then
    echo
    echo "Transport round trip (ours only; REFERENCE D zenoh TCP: 1k 0.2 ms, 10k 1.0 ms, 100k 9.6 ms):"
    echo
    echo "| nodes | median of run medians, µs | run medians, µs |"
    echo "|---|---|---|"
    for n in 1000 10000 100000; do
        echo "| $n | $(fmt "$(answer transport ours $n | median)") | $(answer transport ours $n | paste -sd, - | sed 's/,/, /g') |"
    done
fi
echo
echo "Raw records and logs: $WORK"
