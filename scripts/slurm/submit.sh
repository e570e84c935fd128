#!/usr/bin/env bash
# A voxlod build on a Slurm cluster: plan, an array of map tasks, an array of shard builds, a
# dependent merge (a map/reduce: the input is decoded once in all, not once per shard).
#
#   scripts/slurm/submit.sh INPUT OUT N [build options]
#
# 1. runs `voxlod plan INPUT -o WORK/plan.json --shards N --parts P [build options]` here (a
#    binary PLY of triangles: the vertex list and a sample of the faces only; any other input:
#    one pass, and no parts);
# 2. if the plan has parts, submits voxlod-map.sbatch as the array 0-(P-1), one `voxlod map
#    PLAN --part I` per task (each decodes its face records once and bins them beside the plan);
# 3. submits voxlod-shards.sbatch as the array 0-(N-1), one `voxlod build --plan --shard I` per
#    task, with --dependency=afterok:<map array> (cancelled if a map task fails), with
#    --cpus-per-task and --mem equal to the build's --memory budget;
# 4. submits voxlod-merge.sbatch with --dependency=afterok:<shard array> (cancelled if a shard
#    fails), which writes OUT;
# 5. prints the job ids, and writes them with the settings to WORK/jobs.env for wait.sh and
#    rerun.sh.
#
# WORK is OUT without `.voxlod` plus `.shards/` (VOXLOD_WORK overrides): the plan, the shard
# files and the jobs' logs (WORK/logs/). INPUT, OUT, WORK and the binary must be on a file
# system every node sees. Environment:
#   VOXLOD            the voxlod binary (default: `voxlod` on PATH), made absolute
#   VOXLOD_WORK       the work folder (see above)
#   VOXLOD_CPUS       CPUs per shard task (default: the -j/--threads of the options, else 1)
#   VOXLOD_MERGE_MEM  --mem of the merge job (default: the same as a shard's)
#   VOXLOD_PARTS      parts (map tasks) of the plan (default: N; 0: no map phase, every shard
#                     reads the whole input)
#   SBATCH_PARTITION, SBATCH_ACCOUNT, SBATCH_TIMELIMIT, … : read by sbatch itself.
#
# Example: scripts/slurm/submit.sh /shared/scan.ply /shared/scan.voxlod 16 -r 16384 --memory 8GiB
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
die() { echo "submit.sh: $*" >&2; exit 1; }

if [[ $# -lt 3 ]]; then
  sed -n '2,32p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
input="$1"; out="$2"; shards="$3"; shift 3
opts=("$@")

[[ "$shards" =~ ^[1-9][0-9]*$ ]] || die "N must be a positive number of shards, not '$shards'"
[[ -f "$input" ]] || die "$input: no such input file"
[[ -d "$(dirname "$out")" ]] || die "$out: its folder $(dirname "$out") does not exist"
command -v sbatch >/dev/null || die "sbatch is not on PATH (is this a Slurm login node?)"
voxlod="$(command -v "${VOXLOD:-voxlod}")" || die "voxlod binary '${VOXLOD:-voxlod}' not found (set VOXLOD)"
voxlod="$(realpath "$voxlod")"
input="$(realpath "$input")"
out="$(realpath -m "$out")"
work="$(realpath -m "${VOXLOD_WORK:-${out%.voxlod}.shards}")"
plan="$work/plan.json"
logs="$work/logs"

# The value of option $1 (as `--name V` or `--name=V`) among the build options, if given.
option() {
  local i
  for ((i = 0; i < ${#opts[@]}; i++)); do
    case "${opts[i]}" in
      "$1") echo "${opts[i + 1]:-}"; return ;;
      "$1"=*) echo "${opts[i]#*=}"; return ;;
    esac
  done
}

# The build's memory budget: --memory, else `memory = "…"` in the --config file, else 2GiB
# (voxlod's default), as whole MiB rounded up (voxlod's units: B, K, M, G, T, all powers of 1024).
memory="$(option --memory)"
config="$(option --config)"
if [[ -z "$memory" && -n "$config" && -f "$config" ]]; then
  memory="$(sed -n 's/^[[:space:]]*memory[[:space:]]*=[[:space:]]*"\([^"]*\)".*/\1/p' "$config" | head -n 1)"
fi
memory="${memory:-2GiB}"
mem_mib="$(awk -v s="$memory" 'BEGIN {
  n = s + 0; u = tolower(s); sub(/^[0-9.]+[[:space:]]*/, "", u)
  if (u == "" || u == "b") m = 1 / 1048576; else if (u ~ /^k(i?b)?$/) m = 1 / 1024
  else if (u ~ /^m(i?b)?$/) m = 1; else if (u ~ /^g(i?b)?$/) m = 1024; else if (u ~ /^t(i?b)?$/) m = 1048576
  else exit 1
  v = n * m; r = int(v); if (r < v) r++; if (r < 1) exit 1; print r }')" \
  || die "--memory '$memory' is not a size voxlod reads (examples: 512MiB, 2GiB)"
threads="$(option -j)"; threads="${threads:-$(option --threads)}"
[[ "$threads" =~ ^[1-9][0-9]*$ ]] || threads=1
cpus="${VOXLOD_CPUS:-$threads}"
merge_mem="${VOXLOD_MERGE_MEM:-${mem_mib}M}"
parts_asked="${VOXLOD_PARTS:-$shards}"
[[ "$parts_asked" =~ ^[0-9]+$ ]] || die "VOXLOD_PARTS must be a number of parts, not '$parts_asked'"

mkdir -p "$logs"
echo "plan: $voxlod plan $input -o $plan --shards $shards --parts $parts_asked ${opts[*]}" >&2
summary="$("$voxlod" plan "$input" -o "$plan" --shards "$shards" --parts "$parts_asked" --json "${opts[@]}")"
# the plan's parts (0 when the input cannot be cut: then the shards read the input)
parts="$(sed -n 's/^  "parts": \([0-9]*\),\{0,1\}$/\1/p' <<<"$summary" | head -n 1)"
[[ "$parts" =~ ^[0-9]+$ ]] || die "no part count in voxlod plan's summary: $summary"
if ((parts == 0 && parts_asked > 0)); then
  sed -n 's/^    "\(.*cannot be cut.*\)",\{0,1\}$/warning: \1/p' <<<"$summary" >&2
fi

maps=""
after=()
if ((parts > 0)); then
  maps="$(sbatch --parsable --array="0-$((parts - 1))" --cpus-per-task="$cpus" --mem="${mem_mib}M" \
    --output="$logs/map-%a.out" "$here/voxlod-map.sbatch" "$voxlod" "$plan")" \
    || die "sbatch refused the map array (its message is above); nothing was submitted"
  maps="${maps%%;*}"
  after=(--dependency="afterok:$maps" --kill-on-invalid-dep=yes)
fi
if ! array="$(sbatch --parsable "${after[@]}" --array="0-$((shards - 1))" --cpus-per-task="$cpus" \
  --mem="${mem_mib}M" --output="$logs/shard-%a.out" "$here/voxlod-shards.sbatch" "$voxlod" "$plan")"; then
  [[ -z "$maps" ]] || scancel "$maps" || true
  die "sbatch refused the shard array (its message is above); cancelled the map array${maps:+ $maps}"
fi
array="${array%%;*}"
if ! merge="$(sbatch --parsable --dependency="afterok:$array" --kill-on-invalid-dep=yes \
  --cpus-per-task=1 --mem="$merge_mem" --output="$logs/merge.out" \
  "$here/voxlod-merge.sbatch" "$voxlod" "$plan" "$out")"; then
  scancel "$array" ${maps:+"$maps"} || true
  die "submitting the merge job failed; cancelled the shard array $array${maps:+ and the map array $maps}"
fi
merge="${merge%%;*}"

{
  printf 'VOXLOD=%q\nPLAN=%q\nOUT=%q\nLOGS=%q\nSHARDS=%q\nPARTS=%q\n' "$voxlod" "$plan" "$out" "$logs" "$shards" "$parts"
  printf 'CPUS=%q\nMEM=%q\nMERGE_MEM=%q\n' "$cpus" "${mem_mib}M" "$merge_mem"
  printf 'MAP_JOBS=%q\nARRAY_JOBS=%q\nMERGE_JOB=%q\n' "$maps" "$array" "$merge"
} >"$work/jobs.env"

echo "plan: $plan ($shards shards, $parts parts)"
if ((parts > 0)); then
  echo "map job: $maps (parts 0-$((parts - 1)), $cpus CPUs and ${mem_mib}M each, logs $logs/map-I.out)"
fi
echo "array job: $array (shards 0-$((shards - 1))${maps:+, after every map task succeeds}, $cpus CPUs and ${mem_mib}M each, logs $logs/shard-I.out)"
echo "merge job: $merge (after every shard succeeds; writes $out, log $logs/merge.out)"
echo "wait: $here/wait.sh $work    rerun what failed: $here/rerun.sh $work"
