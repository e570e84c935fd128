#!/usr/bin/env bash
# Waits for the merge job of a voxlod build submitted by submit.sh, then says how it ended:
#
#   scripts/slurm/wait.sh WORK [TIMEOUT_SECONDS]
#
# Exit 0 when the merge job completed (OUT is written). Otherwise exit 1 naming every map task
# and shard whose task did not succeed (state, exit code, log and its last lines) and the command that
# reruns them; exit 3 on timeout (default: none). Polls `scontrol` once a second (no Slurm
# accounting database needed; finished jobs stay visible for the cluster's MinJobAge).
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
die() { echo "wait.sh: $*" >&2; exit 1; }
[[ $# -ge 1 && $# -le 2 ]] || { echo "usage: wait.sh WORK [TIMEOUT_SECONDS]" >&2; exit 2; }
work="$1"
timeout="${2:-0}"
[[ -f "$work/jobs.env" ]] || die "$work/jobs.env is missing: not a folder submit.sh wrote"
# shellcheck source=/dev/null
source "$work/jobs.env"

# The value of FIELD= in one `scontrol show job -o` record.
field() { tr ' ' '\n' <<<"$1" | sed -n "s/^$2=//p" | head -n 1; }

job_state() {
  local rec
  rec="$(scontrol show job -o "$1" 2>/dev/null | head -n 1)" || { echo UNKNOWN; return; }
  field "$rec" JobState
}

# Every task of the array jobs $1 (comma-separated), later jobs (reruns) overriding earlier
# ones, as lines "TASK STATE EXITCODE REASON"; a pending range ("2-5") stays one line.
task_states() {
  local job rec
  declare -A line=()
  for job in ${1//,/ }; do
    while IFS= read -r rec; do
      [[ -n "$rec" ]] || continue
      local task
      task="$(field "$rec" ArrayTaskId)"
      line[$task]="$task $(field "$rec" JobState) $(field "$rec" ExitCode) $(field "$rec" Reason)"
    done < <(scontrol show job -o "$job" 2>/dev/null || true)
  done
  for task in "${!line[@]}"; do echo "${line[$task]}"; done | sort -n
}

start=$SECONDS
while :; do
  state="$(job_state "$MERGE_JOB")"
  case "$state" in
    PENDING | CONFIGURING | RUNNING | COMPLETING | REQUEUED | RESIZING | SUSPENDED) ;;
    *) break ;;
  esac
  if [[ "$timeout" != 0 ]] && ((SECONDS - start >= timeout)); then
    echo "wait.sh: merge job $MERGE_JOB still $state after ${timeout}s" >&2
    exit 3
  fi
  sleep 1
done

if [[ "$state" == COMPLETED ]]; then
  echo "merged: $OUT (merge job $MERGE_JOB, shard jobs $ARRAY_JOBS)"
  exit 0
fi

echo "wait.sh: merge job $MERGE_JOB ended $state; $OUT was not written" >&2
failed_maps=()
while read -r task st code reason; do
  [[ "$st" == COMPLETED ]] && continue
  echo "  map task $task: $st (exit $code, $reason), log $LOGS/map-$task.out" >&2
  if [[ -f "$LOGS/map-$task.out" ]]; then tail -n 5 "$LOGS/map-$task.out" | sed 's/^/    | /' >&2; fi
  [[ "$task" =~ ^[0-9]+$ ]] && failed_maps+=("$task")
done < <(task_states "${MAP_JOBS:-}")
failed=()
while read -r task st code reason; do
  [[ "$st" == COMPLETED ]] && continue
  # shards cancelled because a map task failed are rerun with it
  [[ ${#failed_maps[@]} -gt 0 && "$st" == CANCELLED ]] && continue
  echo "  shard $task: $st (exit $code, $reason), log $LOGS/shard-$task.out" >&2
  if [[ -f "$LOGS/shard-$task.out" ]]; then tail -n 5 "$LOGS/shard-$task.out" | sed 's/^/    | /' >&2; fi
  [[ "$task" =~ ^[0-9]+$ ]] && failed+=("$task")
done < <(task_states "$ARRAY_JOBS")
if [[ ${#failed_maps[@]} -gt 0 ]]; then
  echo "  (the shards waiting for them were cancelled)" >&2
  echo "rerun them and the shards: $here/rerun.sh $work map $(IFS=,; echo "${failed_maps[*]}")" >&2
elif [[ ${#failed[@]} -gt 0 ]]; then
  echo "rerun them: $here/rerun.sh $work $(IFS=,; echo "${failed[*]}")" >&2
elif [[ -f "$LOGS/merge.out" ]]; then
  tail -n 5 "$LOGS/merge.out" | sed 's/^/    | /' >&2
fi
exit 1
