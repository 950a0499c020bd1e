#!/bin/bash
# Long production run with checkpoints (PBS Pro / OpenPBS), resubmitted until time.end.
# Submit: qsub -v SCENE=scene.yaml,OUT=out jobs/pbs_production.sh
# PBS has no "signal before the limit" option: a background timer sends SIGUSR1 to mpiexec
# (Open MPI forwards SIGUSR1 to every rank) 300 s before the walltime; pdemfem then writes a
# final checkpoint on all ranks together and exits 0.
#PBS -N pdemfem-run
#PBS -l select=2:ncpus=64:mpiprocs=64
#PBS -l walltime=24:00:00
#PBS -j oe
set -euo pipefail
: "${SCENE:?qsub -v SCENE=scene.yaml,OUT=out jobs/pbs_production.sh}" "${OUT:?}"
source "${PBS_O_WORKDIR}/jobs/env.sh"
cd "$PBS_O_WORKDIR"
RANKS=$(wc -l < "$PBS_NODEFILE")
WALL=$(qstat -f "$PBS_JOBID" | awk -F'= ' '/Resource_List.walltime/ {print $2}')
IFS=: read -r H M S <<< "$WALL"
LIMIT=$((10#$H * 3600 + 10#$M * 60 + 10#$S))

RESTART=()
if [[ -e "$OUT/checkpoints/latest.h5" ]]; then
    RESTART=(--restart "$OUT/checkpoints/latest.h5")
fi
mpiexec --hostfile "$PBS_NODEFILE" -n "$RANKS" --map-by core --bind-to core \
    pdemfem run "$SCENE" -o "$OUT" --quiet ${RESTART[@]+"${RESTART[@]}"} &
SOLVER=$!
( sleep $((LIMIT - 300)) && kill -USR1 "$SOLVER" 2>/dev/null ) &
TIMER=$!
set +e
wait "$SOLVER"; STATUS=$?
set -e
kill "$TIMER" 2>/dev/null || true

if [[ $STATUS -eq 0 ]] && ! python - "$OUT" "$SCENE" <<'PY'
import sys, csv, yaml
out, scene = sys.argv[1], sys.argv[2]
end = float(yaml.safe_load(open(scene))["time"]["end"])
rows = list(csv.DictReader(open(f"{out}/history.csv")))
sys.exit(0 if rows and float(rows[-1]["time"]) >= end * (1 - 1e-9) else 1)
PY
then
    qsub -W depend=afterany:"$PBS_JOBID" -v SCENE="$SCENE",OUT="$OUT" "$PBS_O_WORKDIR/jobs/pbs_production.sh"
fi
exit $STATUS
