#!/usr/bin/env bash
# Reruns some shards of a voxlod build submitted by submit.sh, then the merge:
#
#   scripts/slurm/rerun.sh WORK K[,K…]
#
# Submits voxlod-shards.sbatch again as `--array=K,…` with the first submission's binary, plan,
# CPUs and memory (a shard that was killed continues from its work folder), cancels the old
# merge job if it is still waiting, and submits a new one with --dependency=afterok on the
# rerun (the other shards' files are already there). Updates WORK/jobs.env for wait.sh.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
die() { echo "rerun.sh: $*" >&2; exit 1; }
[[ $# -eq 2 ]] || { echo "usage: rerun.sh WORK K[,K…]" >&2; exit 2; }
work="$1"
tasks="$2"
[[ -f "$work/jobs.env" ]] || die "$work/jobs.env is missing: not a folder submit.sh wrote"
# shellcheck source=/dev/null
source "$work/jobs.env"
[[ "$tasks" =~ ^[0-9]+(,[0-9]+)*$ ]] || die "'$tasks' is not a list of shard numbers like 3 or 1,4"
for k in ${tasks//,/ }; do
  ((k < SHARDS)) || die "shard $k does not exist: the plan has $SHARDS (0-$((SHARDS - 1)))"
done

scancel "$MERGE_JOB" 2>/dev/null || true
array="$(sbatch --parsable --array="$tasks" --cpus-per-task="$CPUS" --mem="$MEM" \
  --output="$LOGS/shard-%a.out" "$here/voxlod-shards.sbatch" "$VOXLOD" "$PLAN")"
array="${array%%;*}"
merge="$(sbatch --parsable --dependency="afterok:$array" --kill-on-invalid-dep=yes \
  --cpus-per-task=1 --mem="$MERGE_MEM" --output="$LOGS/merge.out" \
  "$here/voxlod-merge.sbatch" "$VOXLOD" "$PLAN" "$OUT")"
merge="${merge%%;*}"

sed -i -e "s|^ARRAY_JOBS=.*|ARRAY_JOBS=$ARRAY_JOBS,$array|" -e "s|^MERGE_JOB=.*|MERGE_JOB=$merge|" \
  "$work/jobs.env"
echo "array job: $array (shards $tasks)"
echo "merge job: $merge (after them; writes $OUT)"
