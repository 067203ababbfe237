#!/usr/bin/env bash
# `twindrive map` on the public 2D SLAM benchmark (Kümmerle et al. 2009,
# "On measuring the accuracy of SLAM algorithms"; the logs and relations in
# ../shared/data/slam2d_benchmark/, not made by this project): each CARMEN
# log mapped as it is (`map --carmen`, from the robot's own odometry), the
# poses scored on the set's relations (`twindrive relations`), beside the
# errors Cartographer and Graph Mapping published (Hess et al. 2016, Table
# II) and Cartographer's wall-clock time (its Table V, a Xeon E5-1650; ours
# on this machine, one run: a time on a shared machine is indicative only).
# Prints one table on stdout, one progress line per data set on stderr.
# Usage: bench/slam_benchmark.sh [SET...]   (from any directory; SET among
#        aces intel fr079 mit-csail fr-hospital; default all five)
#   SMOKE=1   the dev build and the first 120 s of ACES only (a few seconds)
#   DATA=DIR  the benchmark's folder (default ../shared/data/slam2d_benchmark)
#   PICTURES=DIR  also writes each map as DIR/SET.png (map.pgm, shrunk to at
#             most 900 pixels a side, a block's darkest cell kept)
set -euo pipefail
SMOKE=${SMOKE:-0}
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
source bench/profile.sh
DATA=${DATA:-$ROOT/../shared/data/slam2d_benchmark}
if [[ ! -d $DATA ]]; then
    echo "slam_benchmark: SKIPPED: $DATA is absent" >&2
    exit 0
fi
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

build -p twindrive --bin twindrive
bin=./target/$PROFILE_DIR/twindrive

# set folder log relations carto_trans_m carto_rot_deg gm_trans_m gm_rot_deg carto_wall_s
# Published numbers copied from ../shared/data/slam2d_benchmark/PUBLISHED.md:
# Hess et al. 2016 Table II (absolute translational m, absolute rotational
# deg, mean ± sd; GM = Graph Mapping as quoted there from Kümmerle 2009) and
# Table V (wall clock, s). The hospital's are its "local" relations.
SETS=(
    "aces aces aces.rebuilt.clf.gz aces.relations 0.0375±0.0426 0.373±0.469 0.044±0.044 0.4±0.4 41"
    "intel intel intel.rebuilt.clf.gz intel.relations 0.0229±0.0239 0.453±1.335 0.031±0.026 1.3±4.7 179"
    "fr079 fr079 fr079.rebuilt.clf.gz fr079.relations 0.0452±0.0354 0.538±0.718 0.056±0.042 0.6±0.6 62"
    "mit-csail mit-csail mit-csail.clf.gz mit-csail.relations 0.0319±0.0363 0.369±0.365 0.004±0.009 0.05±0.08 35"
    "fr-hospital fr-hospital fr-clinic_robotlaser.rebuilt.clf.gz fr-clinic.relations 0.1078±0.1943 0.747±2.047 0.143±0.180 0.9±2.2 10"
)
wanted=("$@")
until=()
if [[ $SMOKE == 1 ]]; then
    wanted=(aces)
    until=(--until-s 120)
fi

# measure OUT_PREFIX CMD...: runs CMD; OUT_PREFIX.wall (s) and .rss (peak kB).
measure() {
    local prefix=$1
    shift
    local start=$EPOCHREALTIME status=0
    if [[ -x /usr/bin/time ]]; then
        /usr/bin/time -f '%M' -o "$prefix.rss" "$@" || status=$?
    else
        python3 -c 'import resource, subprocess, sys
code = subprocess.call(sys.argv[2:])
open(sys.argv[1], "w").write("%d\n" % resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
sys.exit(code)' "$prefix.rss" "$@" || status=$?
    fi
    awk -v a="$start" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.1f\n", b - a }' > "$prefix.wall"
    return $status
}

rows="$WORK/rows.tsv"
: > "$rows"
for spec in "${SETS[@]}"; do
    read -r set folder log relations carto_t carto_r gm_t gm_r carto_s <<< "$spec"
    if [[ ${#wanted[@]} -gt 0 && ! " ${wanted[*]} " =~ " $set " ]]; then
        continue
    fi
    out="$WORK/$set"
    # site.toml's robot needs wheels; the map does not use them (the
    # log's odometry places the scans).
    status=0
    measure "$WORK/$set" "$bin" map --carmen "$DATA/$folder/$log" "${until[@]}" \
        --wheel-diameter-m 0.2 --wheelbase-m 0.4 --out "$out" \
        > "$WORK/$set.stdout" 2> "$WORK/$set.stderr" || status=$?
    if [[ ! -f $out/poses.tum ]]; then
        echo "slam_benchmark: $set: map failed (exit $status):" >&2
        cat "$WORK/$set.stderr" >&2
        exit 1
    fi
    # A map whose site.toml could not be placed still wrote its poses.
    note=""
    [[ $status == 0 ]] || note=" (map exit $status: $(tail -1 "$WORK/$set.stderr"))"
    "$bin" relations --relations "$DATA/$folder/$relations" "$out/poses.tum" --json > "$WORK/$set.score.json"
    scans=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["scans"])' "$out/map_report.json")
    wall=$(cat "$WORK/$set.wall")
    rss_mb=$(tail -1 "$WORK/$set.rss" | awk '{ printf "%.0f", $1 / 1024 }')
    read -r matched total trans_m trans_sd rot_deg rot_sd < <(python3 -c 'import json, sys
s = json.load(open(sys.argv[1])); e = s["errors"]
print(s["matched"], s["relations"], e["abs_trans_m"]["mean"], e["abs_trans_m"]["std"], e["abs_rot_deg"]["mean"], e["abs_rot_deg"]["std"])' \
        "$WORK/$set.score.json")
    ours_t=$(awk -v m="$trans_m" -v s="$trans_sd" 'BEGIN { printf "%.4f±%.4f", m, s }')
    ours_r=$(awk -v m="$rot_deg" -v s="$rot_sd" 'BEGIN { printf "%.3f±%.3f", m, s }')
    printf '%s\t%s\t%s\t%s\t%s/%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' \
        "$set" "$scans" "$ours_t" "$ours_r" "$matched" "$total" "$carto_t" "$carto_r" "$gm_t" "$gm_r" \
        "$wall" "$carto_s" "$rss_mb" >> "$rows"
    if [[ -n ${PICTURES:-} ]]; then
        mkdir -p "$PICTURES"
        python3 - "$out/map.pgm" "$PICTURES/$set.png" <<'PY'
import struct, sys, zlib
data = open(sys.argv[1], "rb").read()
fields, i = [], 0
while len(fields) < 4:
    while data[i:i + 1].isspace():
        i += 1
    if data[i:i + 1] == b"#":
        i = data.index(b"\n", i)
        continue
    j = i
    while not data[j:j + 1].isspace():
        j += 1
    fields.append(data[i:j])
    i = j
w, h, px = int(fields[1]), int(fields[2]), data[i + 1:]
k = max(1, -(-max(w, h) // 900))
ow, oh = -(-w // k), -(-h // k)
rows = []
for oy in range(oh):
    row = bytearray(ow)
    for ox in range(ow):
        row[ox] = min(px[y * w + x] for y in range(oy * k, min(h, oy * k + k)) for x in range(ox * k, min(w, ox * k + k)))
    rows.append(b"\x00" + bytes(row))
def chunk(kind, body):
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
open(sys.argv[2], "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", ow, oh, 8, 0, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(b"".join(rows), 9)) + chunk(b"IEND", b""))
PY
    fi
    echo "slam_benchmark: $set: $scans scans mapped in $wall s, peak ${rss_mb} MB; $ours_t m, $ours_r deg on $matched/$total relations$note" >&2
done

if [[ $SMOKE == 1 ]]; then
    echo "(smoke: the first 120 s of ACES in the dev build; the numbers mean nothing)"
fi
{
    printf 'set\tscans\tours_trans_m\tours_rot_deg\tmatched\tcarto_trans_m\tcarto_rot_deg\tgm_trans_m\tgm_rot_deg\tours_wall_s\tcarto_wall_s\tpeak_rss_mb\n'
    cat "$rows"
} | column -t -s $'\t'
