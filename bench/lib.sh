# Shared by bench/compare.sh and bench/guard.sh (sourced; needs ROOT, log and die):
# finding or building our release bench executables, and the median of numbers on stdin.

# candidate cargo target folders, in order of preference
target_dirs() {
    [[ -n ${COSIM_TARGET_DIR:-} ]] && echo "$COSIM_TARGET_DIR"
    [[ -n ${CARGO_TARGET_DIR:-} ]] && echo "$CARGO_TARGET_DIR"
    echo "$HOME/.cache/cosim-target"
    echo "$ROOT/target"
}

# newest executable release/deps/<name>-<hash> in the candidate target folders
find_bench() {
    local name=$1 best="" t bt=0 d f
    while read -r d; do
        for f in "$d"/release/deps/"$name"-*; do
            [[ -f $f && -x $f && $f != *.d ]] || continue
            t=$(stat -c %Y "$f")
            if ((t > bt)); then bt=$t; best=$f; fi
        done
    done < <(target_dirs)
    echo "$best"
}

# newest release executable <name> (a binary, not a bench) in the candidate target folders
find_release_bin() {
    local name=$1 best="" t bt=0 d
    while read -r d; do
        [[ -f $d/release/$name && -x $d/release/$name ]] || continue
        t=$(stat -c %Y "$d/release/$name")
        if ((t > bt)); then bt=$t; best=$d/release/$name; fi
    done < <(target_dirs)
    echo "$best"
}

# bench name -> cargo package and flags (static_beam builds without the node feature; `cosim`
# is the release binaries of a run)
build_bench() {
    case $1 in
    cosim) (cd "$ROOT" && cargo build --release -p coordinator -p dem-node -p fem-node --bins) ;;
    dense_bed) (cd "$ROOT" && cargo bench --no-run -p dem-node --bench dense_bed) ;;
    pour) (cd "$ROOT" && cargo bench --no-run -p dem-node --bench pour) ;;
    polyhedron_bed) (cd "$ROOT" && cargo bench --no-run -p dem-node --bench polyhedron_bed) ;;
    superquadric_bed) (cd "$ROOT" && cargo bench --no-run -p dem-node --bench superquadric_bed) ;;
    static_beam) (cd "$ROOT" && cargo bench --no-run -p fem-node --no-default-features --bench static_beam) ;;
    transport) (cd "$ROOT" && cargo bench --no-run -p proto --bench transport) ;;
    esac
}

ours_bin() {
    local b
    b=$(find_bench "$1")
    if [[ -z $b ]]; then
        command -v cargo >/dev/null || die "no $1 bench executable found and no cargo to build it"
        log "no $1 bench executable found: building it (cargo bench --no-run)"
        build_bench "$1" >&2
        b=$(find_bench "$1")
        [[ -n $b ]] || die "built $1 but cannot find release/deps/$1-*; set COSIM_TARGET_DIR"
    fi
    echo "$b"
}

# median of the numbers on stdin (one per line)
median() { sort -g | awk '{v[NR]=$1} END{if (NR == 0) print ""; else if (NR % 2) print v[(NR+1)/2]; else print (v[NR/2]+v[NR/2+1])/2}'; }
