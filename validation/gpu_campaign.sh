#!/bin/bash
# One device visit for tier 2 on refined levels (docs/PERFORMANCE.md, "Tier 2 on levels on a GPU"), inside
# CAMPAIGN_S seconds (default 530: a 9-minute visit with its start) including compilation, in four phases that each
# end at a deadline, so that a slow phase costs the next ones time, never the visit:
#   1. ladder  `iceresist validate --full --cases ship_tier2_amr`: the rungs at 3, 4.5, 6 and 9 cells per cube in
#              turn, each row written to ladder.csv as its rung ends (the first rung pays the compilation), until
#              LADDER_END s;
#   2. rate    `validation.bench ship --preset quick --amr --records 2 --by-label`: the quick case on levels, its
#              fine-equivalent MLUPS, the level exchange's share, the projected time, until RATE_END s;
#   3. sweep   `iceresist sweep --preset quick --tier 2 --amr` (six cases), until PAPER_S s are left; a case cut off
#              leaves its records so far (CASE.partial.h5);
#   4. paper   `validation.bench ship --preset paper --amr --records 1 --fit-gib 70 --fit-gib 125`: the paper's levels
#              counted, built and one record timed (its rate and projected time), in the PAPER_S s left.
# The plan, from the 2-core x86 VM (2026-12-07; levels counted by `Tier2Model.plan`): the rungs hold 1.6e6, 4.8e6,
# 9.0e6 and 3.3e7 leaf cells and take 4.8e9, 2.1e10, 5.1e10 and 2.8e11 cell updates; the quick case 8.5e6 cells
# (4.7e10 updates); the paper's levels 1.5e8 cells (59 GB of populations on the finest level, 1.9e13 updates).
# The host builds a level's tables at about 1 s per 1e6 leaf cells (a rebuild at a regrid about 1.4 s), counts the
# paper's levels in 64 s; at the 625 MLUPS of the uniform coupled step on an H100 the first three rungs take about
# 2 min of stepping and the fourth 7 min, so the ladder ends within its deadline at the third rung unless the step on
# levels is faster; a quick case needs 80 s at 600 MLUPS; the paper's build (counting, tables, 59 GB on the device)
# is what phase 4 waits for. Everything a record of the visit needs lands in OUT/campaign/ (ladder.csv, the rungs'
# and cases' result files, the bench rows, every log, phases.txt with each phase's start, end and exit status);
# checkpoints and scratch stay out of OUT. CAMPAIGN_BACKEND (default cuda) runs the same phases elsewhere (cpu: a
# check of the plumbing with short deadlines).
#
#   bash validation/gpu_campaign.sh OUT
set -u
OUT=${1:-gpu-check}
PYTHON=${PYTHON:-python3}
BACKEND=${CAMPAIGN_BACKEND:-cuda}
CAMPAIGN_S=${CAMPAIGN_S:-530}
LADDER_END=${LADDER_END:-270}
RATE_END=${RATE_END:-340}
PAPER_S=${PAPER_S:-170}
dest="$OUT/campaign"
mkdir -p "$dest"
scratch=$(mktemp -d)
start=$(date +%s)
elapsed() { echo $(( $(date +%s) - start )); }

# phase NAME DEADLINE_S LOG COMMAND...: COMMAND until DEADLINE_S seconds after the start, its output in LOG; at the
# deadline an interrupt (SIGINT: the engine closes the files it has written), 20 s later a kill
phase() {
  local name=$1 deadline=$2 log=$3
  shift 3
  local t0 left rc
  t0=$(elapsed)
  left=$(( deadline - t0 ))
  if [ "$left" -le 5 ]; then
    echo "$name: skipped at $t0 s (deadline $deadline s)" | tee -a "$dest/phases.txt"
    return
  fi
  echo "== $name from $t0 s until $deadline s"
  timeout --signal=INT --kill-after=20 "$left" "$@" > "$dest/$log" 2>&1
  rc=$?
  echo "$name: $t0 s to $(elapsed) s, exit $rc$([ $rc -eq 124 ] && echo ' (cut off at its deadline)')" \
    | tee -a "$dest/phases.txt"
}

# keep FROM TO: the tables, result files and logs under FROM (not checkpoints) copied to TO, same paths
keep() {
  local from=$1 to f
  [ -d "$from" ] || return 0
  to=$(mkdir -p "$2" && cd "$2" && pwd)
  (cd "$from" && find . -type f \( -name '*.csv' -o -name '*.json' -o -name '*.md' -o -name '*.h5' \) \
     ! -name '*checkpoint*' -size -50M) | while read -r f; do
    mkdir -p "$to/$(dirname "$f")" && cp "$from/$f" "$to/$f"
  done
}

echo "campaign on $BACKEND, $CAMPAIGN_S s: ladder until $LADDER_END s, rate until $RATE_END s, sweep until" \
     "$(( CAMPAIGN_S - PAPER_S )) s, paper until $CAMPAIGN_S s" | tee "$dest/phases.txt"
phase ladder "$LADDER_END" ladder.log "$PYTHON" -m iceresist validate --full --cases ship_tier2_amr \
  --backend "$BACKEND" --out "$scratch/validate" --no-progress
keep "$scratch/validate" "$dest/validate"
phase rate "$RATE_END" rate.log "$PYTHON" -m validation.bench ship --preset quick --amr --backend "$BACKEND" \
  --records 2 --by-label --json
phase sweep "$(( CAMPAIGN_S - PAPER_S ))" sweep.log "$PYTHON" -m iceresist sweep --preset quick --tier 2 --amr \
  --backend "$BACKEND" --output "$scratch/sweep" --no-progress
keep "$scratch/sweep" "$dest/sweep"
phase paper "$CAMPAIGN_S" paper.log "$PYTHON" -m validation.bench ship --preset paper --amr --backend "$BACKEND" \
  --records 1 --fit-gib 70 --fit-gib 125 --json
rm -rf "$scratch"
echo "campaign done at $(elapsed) s: $dest" | tee -a "$dest/phases.txt"
grep -h '^{' "$dest/rate.log" "$dest/paper.log" 2>/dev/null | head -4
[ -f "$dest/validate/ladder.csv" ] && cat "$dest/validate/ladder.csv"
exit 0
