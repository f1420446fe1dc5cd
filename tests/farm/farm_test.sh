#!/usr/bin/env bash
# The farm against a real Slurm: each case starts its own one-node cluster (cluster.sh), submits tests/scenes/farm.yaml
# through `ganache farm` and checks the outputs byte for byte against a local `ganache run` of the same scene.
#   farm_test.sh graph|requeue|bad_input GANACHE
#   graph      the whole job graph (simulate, 3 surface and 3 render tasks, assemble) and its merged report
#   requeue    the simulate job requeued in the middle of its run resumes from its checkpoint, outputs unchanged
#   bad_input  no Slurm on the PATH, a controller that does not answer, no such partition, an output folder the
#              partition's nodes cannot see, a job no node can hold, an option sbatch refuses: clear errors, nothing
#              submitted
# Exit 77 (skipped) without root or without Slurm's packages (scripts/test.sh installs them).
set -euo pipefail
case_name=${1:?usage: farm_test.sh CASE GANACHE}
ganache=$(realpath "${2:?usage: farm_test.sh CASE GANACHE}")
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
scene="$here/../scenes/farm.yaml"
work=$(mktemp -d /tmp/ganache-farm-test.XXXXXX)
cleanup() {
  "$here/cluster.sh" stop "$work/cluster" >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT

fail() {
  echo "FAIL: $*" >&2
  for log in "$work"/farm/farm/logs/*.log; do [ -f "$log" ] && { echo "--- $log" >&2; tail -n 15 "$log" >&2; }; done
  exit 1
}

start_cluster() {
  local status=0
  "$here/cluster.sh" start "$work/cluster" >"$work/cluster.env" || status=$?
  ((status == 0)) || exit "$status"  # 77: no root or no Slurm here
  source "$work/cluster.env"
}

# Polls until the farm's jobs have all left the queue (a generous limit for a loaded machine; no fixed delays).
wait_for_queue() {
  local deadline=$((SECONDS + 600))
  while [ -n "$(squeue -h 2>/dev/null)" ]; do
    ((SECONDS < deadline)) || fail "the jobs did not finish within 600 s: $(squeue)"
    sleep 0.5
  done
}

# Every output of the local run, byte for byte (checkpoints carry the run's own timings, report.json its times).
same_outputs() {
  local local_out=$1 farm_out=$2 count=0
  while IFS= read -r f; do
    cmp -s "$local_out/$f" "$farm_out/$f" || fail "$f differs between the local run and the farm"
    count=$((count + 1))
  done < <(cd "$local_out" && find . -type f ! -name report.json ! -path './cache/*' ! -path './checkpoints/*' | sort)
  for d in sample particles surface mesh preview; do
    [ "$(ls "$local_out/$d" | wc -l)" = "$(ls "$farm_out/$d" | wc -l)" ] || fail "$d/ holds other files on the farm"
  done
  ((count > 40)) || fail "only $count outputs compared"
  echo "$count outputs identical"
}

job_id() { sed -n "/\"stage\": \"$1\"/,/\"id\"/s/.*\"id\": \"\([0-9]*\)\".*/\1/p" "$work/farm/farm/farm.json"; }

case "$case_name" in
graph)
  start_cluster
  "$ganache" run "$scene" --out "$work/local" 2>/dev/null
  "$ganache" farm "$scene" --out "$work/farm" --chunk 5 >"$work/submit.txt" || fail "submission: $(cat "$work/submit.txt")"
  cat "$work/submit.txt"
  [ "$(grep -c '^submitted' "$work/submit.txt")" = 4 ] || fail "expected 4 jobs submitted"
  grep -q -- '--array=0-2' "$work/farm/farm/surface.sbatch" || fail "12 frames in chunks of 5 should be 3 surface tasks"
  grep -q -- "--dependency" "$work/farm/farm/surface.sbatch" && fail "dependencies belong to the submission"
  wait_for_queue
  "$ganache" farm status "$work/farm" | tee "$work/status.txt"
  grep -q '12/12 frames rendered' "$work/status.txt" || fail "status does not show every frame rendered"
  grep -q '"status": "done"' "$work/farm/report.json" || fail "the merged report does not say done"
  for stage in simulate surface render assemble; do
    grep -q "\"$stage\": \"$(job_id "$stage")\"" "$work/farm/report.json" || fail "report.json lacks the $stage job id"
  done
  [ "$(grep -c '"report": ' "$work/farm/report.json")" = 9 ] || fail "report.json should list 9 task reports"
  same_outputs "$work/local" "$work/farm"

  # A task that fails is named by `status` with the command that reruns it alone; rerun, a task redoes only what is
  # missing or out of date.
  printf 'v 0 0 0\nv 1 0 0\nf 1 2 3\n' >"$work/farm/mesh/farm.0007.obj"
  sbatch -Q --array=1 "$work/farm/farm/render.sbatch"
  wait_for_queue
  "$ganache" farm status "$work/farm" >"$work/status.txt"
  grep -q "not done: render frames 6-10: failed: render: frame 7: .*farm.0007.obj:3" "$work/status.txt" ||
    fail "status does not name the failed render task: $(cat "$work/status.txt")"
  grep -qF "rerun: sbatch --array=1 $work/farm/farm/render.sbatch" "$work/status.txt" || fail "no rerun command"
  rm "$work/farm/mesh/farm.0007.obj"
  sbatch -Q --array=1 "$work/farm/farm/surface.sbatch"
  wait_for_queue
  sbatch -Q --array=1 "$work/farm/farm/render.sbatch"
  wait_for_queue
  "$ganache" farm status "$work/farm" >"$work/status.txt"
  grep -q "not done" "$work/status.txt" && fail "the rerun task did not mend the frame: $(cat "$work/status.txt")"
  grep -q '"frames_done": 1,' "$work/farm/farm/reports/surface.6-10.json" || fail "the rerun redid more than frame 7"
  same_outputs "$work/local" "$work/farm"

  # Time limits from measured costs: the farm's merged report, and a local run's, both give them.
  for out in "$work/farm" "$work/local"; do
    "$ganache" farm "$scene" --out "$out" --chunk 5 --dry-run >"$work/plan.txt"
    [ "$(grep -c 'min (measured)' "$work/plan.txt")" = 3 ] || fail "no measured time limits: $(cat "$work/plan.txt")"
    grep -q -- '--time=' "$out/farm/simulate.sbatch" || fail "the simulate script has no time limit"
  done
  [ -z "$(squeue -h)" ] || fail "a dry run submitted jobs"
  ;;
requeue)
  start_cluster
  # At half the radius the simulation takes long enough (about 0.6 s a frame on 2 cores) to be caught mid-run.
  "$ganache" farm "$scene" --out "$work/farm" --quality 0.5 --chunk 4 >"$work/submit.txt" || fail "submission"
  simulate=$(job_id simulate)
  deadline=$((SECONDS + 300))
  until [ -e "$work/farm/particles/farm.0003.vdb" ]; do
    ((SECONDS < deadline)) || fail "frame 3 was never simulated"
    sleep 0.1
  done
  [ "$(squeue -h -j "$simulate" -o %T)" = RUNNING ] || fail "the simulation ended before it could be requeued"
  scontrol requeue "$simulate"
  until [ "$(squeue -h -j "$simulate" -o %T)" = PENDING ]; do
    ((SECONDS < deadline)) || fail "the requeued job never came back to the queue"
    sleep 0.2
  done
  # A requeued job waits out the credential lifetime (minutes); 2 s on, its old credential no longer applies.
  scontrol update jobid="$simulate" starttime=now+2

  # Then the warning Slurm gives before a time limit (USR1 to the batch shell; sent by hand here, since Slurm's own
  # timing is loose): the job stops with a checkpoint and requeues itself.
  until [ -e "$work/farm/particles/farm.0007.vdb" ]; do
    ((SECONDS < deadline)) || fail "frame 7 was never simulated"
    sleep 0.1
  done
  scontrol show job "$simulate" | grep -q 'Restarts=1' || fail "frame 7 should come from the requeued run"
  scancel --batch --signal=USR1 "$simulate"
  until scontrol show job "$simulate" | grep -q 'JobState=PENDING.*\|Restarts=2'; do
    ((SECONDS < deadline)) || fail "the job did not requeue itself: $(scontrol show job "$simulate")"
    sleep 0.2
  done
  until [ "$(squeue -h -j "$simulate" -o %T)" = PENDING ]; do
    ((SECONDS < deadline)) || fail "the job requeued by itself never came back to the queue"
    sleep 0.2
  done
  scontrol update jobid="$simulate" starttime=now+2
  "$ganache" run "$scene" --out "$work/local" --quality 0.5 2>/dev/null
  wait_for_queue
  grep -q 'resumed at frame' "$work/farm/farm/reports/simulate.json" || fail "the requeued simulation did not resume"
  grep -q 'DUE TO JOB REQUEUE' "$work"/farm/farm/logs/simulate.*.log || fail "the log does not show the requeue"
  grep -q 'requeued to go on from it' "$work"/farm/farm/logs/simulate.*.log ||
    fail "the log does not show the job requeueing itself"
  grep -q '"status": "done"' "$work/farm/report.json" || fail "the merged report does not say done"
  same_outputs "$work/local" "$work/farm"
  ;;
bad_input)
  expect() {  # expect EXIT-CODE TEXT COMMAND...: the command fails with that code and says TEXT
    local code=$1 text=$2 status=0
    shift 2
    "$@" >"$work/out.txt" 2>&1 || status=$?
    [ "$status" = "$code" ] || fail "$* exited $status, expected $code: $(cat "$work/out.txt")"
    grep -qF -- "$text" "$work/out.txt" || fail "$* does not say '$text': $(cat "$work/out.txt")"
    [ -z "$(squeue -h 2>/dev/null)" ] || fail "$* left jobs submitted"
  }
  mkdir -p "$work/empty"
  expect 2 '`sbatch` is not on the PATH' env PATH="$work/empty" "$ganache" farm "$scene" --out "$work/farm"
  start_cluster
  good_conf=$SLURM_CONF
  # A controller that does not answer: the same cluster's configuration with a port nobody listens on.
  sed 's/^SlurmctldPort=.*/SlurmctldPort=9/' "$good_conf" >"$work/down.conf"
  expect 1 'the Slurm controller does not answer' env SLURM_CONF="$work/down.conf" "$ganache" farm "$scene" --out "$work/farm"
  expect 2 "no such partition (partitions: elsewhere, main (default))" \
    "$ganache" farm "$scene" --out "$work/farm" --partition nosuch
  expect 2 'they would not see it' "$ganache" farm "$scene" --out "$work/farm" --partition elsewhere
  expect 2 'more than the largest node' "$ganache" farm "$scene" --out "$work/farm" --quality 0.04
  expect 2 'Slurm would refuse the simulate job' "$ganache" farm "$scene" --out "$work/farm" --sbatch=--gres=nosuch:1
  expect 2 'no farm submission here' "$ganache" farm status "$work/nothing"
  [ ! -e "$work/farm/farm/farm.json" ] || fail "a refused submission left a plan behind"

  # sbatch refuses the third job: the two already submitted are cancelled.
  mkdir -p "$work/bin"
  cat >"$work/bin/sbatch" <<FAKE
#!/bin/bash
if [[ " \$* " != *" --test-only "* ]] && [ "\$(ls "$work/bin" | grep -c '^submitted')" = 2 ]; then
  echo "sbatch: error: Batch job submission failed: refused by the test" >&2
  exit 1
fi
[[ " \$* " == *" --test-only "* ]] || touch "$work/bin/submitted.\$RANDOM\$RANDOM"
exec $(command -v sbatch) "\$@"
FAKE
  chmod +x "$work/bin/sbatch"
  PATH="$work/bin:$PATH" "$ganache" farm "$scene" --out "$work/farm" >"$work/out.txt" 2>&1 && fail "a refused job went unnoticed"
  grep -q 'refused by the test' "$work/out.txt" || fail "sbatch's refusal is not shown: $(cat "$work/out.txt")"
  grep -q 'were cancelled: nothing is left submitted' "$work/out.txt" || fail "no word of the cancelled jobs"
  deadline=$((SECONDS + 60))
  until [ -z "$(squeue -h)" ]; do
    ((SECONDS < deadline)) || fail "the jobs submitted before the refusal are still queued: $(squeue)"
    sleep 0.2
  done

  # A graph still queued (here: told to wait an hour) keeps a second one out of its folder.
  "$ganache" farm "$scene" --out "$work/farm" --sbatch=--begin=now+3600 >/dev/null || fail "a graph held for an hour"
  queued=$(squeue -h -r | wc -l)
  status=0
  "$ganache" farm "$scene" --out "$work/farm" >"$work/out.txt" 2>&1 || status=$?
  [ "$status" = 2 ] && grep -q 'are still in the queue' "$work/out.txt" ||
    fail "a second graph into a busy folder: exit $status: $(cat "$work/out.txt")"
  [ "$(squeue -h -r | wc -l)" = "$queued" ] || fail "the second graph submitted jobs: $(squeue)"
  ;;
*)
  echo "unknown case $case_name" >&2
  exit 2
  ;;
esac
echo "PASS: farm $case_name"
