#!/usr/bin/env bash
# Reruns the tasks of a voxlod build submitted by submit.sh that did not finish, then the merge:
#
#   scripts/slurm/rerun.sh WORK              # every map task and shard whose output is missing
#   scripts/slurm/rerun.sh WORK K[,K…]       # shards K… only (as wait.sh prints)
#   scripts/slurm/rerun.sh WORK map K[,K…]   # map tasks K… only, and the shards missing after
#
# A map task is done when its committed output WORK/part-IIII.json exists, a shard when its
# file WORK/shard-IIII.vlshard exists (a shard cancelled because a map task failed never
# wrote one). Submits voxlod-map.sbatch again for the map tasks to rerun (`--array=K,…`),
# voxlod-shards.sbatch for the shards to rerun with --dependency=afterok on that map rerun,
# cancels the old merge job if it is still waiting, and submits a new one after them; all with
# the first submission's binary, plan, CPUs and memory (a task that was killed continues from
# its work folder). Updates WORK/jobs.env for wait.sh.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
die() { echo "rerun.sh: $*" >&2; exit 1; }
[[ $# -ge 1 && $# -le 3 ]] || { echo "usage: rerun.sh WORK [[map] K[,K…]]" >&2; exit 2; }
work="$1"
[[ -f "$work/jobs.env" ]] || die "$work/jobs.env is missing: not a folder submit.sh wrote"
# shellcheck source=/dev/null
source "$work/jobs.env"
PARTS="${PARTS:-0}"
MAP_JOBS="${MAP_JOBS:-}"
dir="$(dirname "$PLAN")"

# The numbers 0..$1-1 whose file "$dir/PREFIX%04d.SUFFIX" is missing, comma-separated.
missing() {
  local n=$1 prefix=$2 suffix=$3 k out=()
  for ((k = 0; k < n; k++)); do
    [[ -e "$(printf '%s/%s%04d.%s' "$dir" "$prefix" "$k" "$suffix")" ]] || out+=("$k")
  done
  (IFS=,; echo "${out[*]}")
}
# Checks a list of task numbers below $2 (what: $3).
check_list() {
  [[ "$1" =~ ^[0-9]+(,[0-9]+)*$ ]] || die "'$1' is not a list of $3 numbers like 3 or 1,4"
  local k
  for k in ${1//,/ }; do
    ((k < $2)) || die "$3 $k does not exist: the plan has $2 (0-$(($2 - 1)))"
  done
}

maps="" shards=""
case $# in
  1) maps="$(missing "$PARTS" part- json)"; shards="$(missing "$SHARDS" shard- vlshard)" ;;
  2) shards="$2"; check_list "$shards" "$SHARDS" shard ;;
  3) [[ "$2" == map ]] || die "the second argument is 'map' (rerun map tasks) or a list of shards"
     maps="$3"; check_list "$maps" "$PARTS" "map task"; shards="$(missing "$SHARDS" shard- vlshard)" ;;
esac
[[ -n "$maps$shards" ]] || die "every map output and shard file is there: nothing to rerun (the merge: sbatch voxlod-merge.sbatch, see README.md)"

scancel "$MERGE_JOB" 2>/dev/null || true
after=()
map_job=""
if [[ -n "$maps" ]]; then
  map_job="$(sbatch --parsable --array="$maps" --cpus-per-task="$CPUS" --mem="$MEM" \
    --output="$LOGS/map-%a.out" "$here/voxlod-map.sbatch" "$VOXLOD" "$PLAN")"
  map_job="${map_job%%;*}"
  after=(--dependency="afterok:$map_job" --kill-on-invalid-dep=yes)
  echo "map job: $map_job (parts $maps)"
fi
last="$map_job"
array=""
if [[ -n "$shards" ]]; then
  array="$(sbatch --parsable "${after[@]}" --array="$shards" --cpus-per-task="$CPUS" --mem="$MEM" \
    --output="$LOGS/shard-%a.out" "$here/voxlod-shards.sbatch" "$VOXLOD" "$PLAN")"
  array="${array%%;*}"
  last="$array"
  echo "array job: $array (shards $shards)"
fi
merge="$(sbatch --parsable --dependency="afterok:$last" --kill-on-invalid-dep=yes \
  --cpus-per-task=1 --mem="$MERGE_MEM" --output="$LOGS/merge.out" \
  "$here/voxlod-merge.sbatch" "$VOXLOD" "$PLAN" "$OUT")"
merge="${merge%%;*}"

add() { local old=$1 new=$2; [[ -z "$new" ]] && { echo "$old"; return; }; echo "${old:+$old,}$new"; }
sed -i -e "s|^ARRAY_JOBS=.*|ARRAY_JOBS=$(add "$ARRAY_JOBS" "$array")|" -e "s|^MERGE_JOB=.*|MERGE_JOB=$merge|" \
  "$work/jobs.env"
if grep -q '^MAP_JOBS=' "$work/jobs.env"; then
  sed -i "s|^MAP_JOBS=.*|MAP_JOBS=$(add "$MAP_JOBS" "$map_job")|" "$work/jobs.env"
fi
echo "merge job: $merge (after them; writes $OUT)"
