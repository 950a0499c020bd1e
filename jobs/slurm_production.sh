#!/bin/bash
# Long production run with checkpoints, resubmitted until the scene's time.end is reached.
# Submit: sbatch jobs/slurm_production.sh scene.yaml out      (the scene needs a checkpoint key,
#         e.g. checkpoint: {every: 0.01, keep: 2, dir: out/checkpoints})
# Slurm sends SIGUSR1 to this batch shell 300 s before the time limit (B: = batch shell only);
# the trap forwards it to the solver, which finishes its step, writes a final checkpoint on all
# ranks together and exits 0.  The job then resubmits itself to continue from latest.h5.
#SBATCH --job-name=pdemfem-run
#SBATCH --nodes=2
#SBATCH --ntasks-per-node=64
#SBATCH --cpus-per-task=1
#SBATCH --time=24:00:00
#SBATCH --signal=B:USR1@300
#SBATCH --output=%x-%j.out
set -euo pipefail
SCENE="${1:?usage: sbatch jobs/slurm_production.sh SCENE.yaml OUTDIR}"
OUT="${2:?usage: sbatch jobs/slurm_production.sh SCENE.yaml OUTDIR}"
source "${SLURM_SUBMIT_DIR}/jobs/env.sh"
cd "$SLURM_SUBMIT_DIR"

RESTART=()
if [[ -e "$OUT/checkpoints/latest.h5" ]]; then
    # Any rank count can restart any checkpoint (add --force only after a deliberate scene edit).
    RESTART=(--restart "$OUT/checkpoints/latest.h5")
fi
srun --cpu-bind=cores pdemfem run "$SCENE" -o "$OUT" --quiet ${RESTART[@]+"${RESTART[@]}"} &
SOLVER=$!
trap 'echo "time limit near: asking pdemfem for a final checkpoint"; kill -USR1 "$SOLVER"' USR1
# `wait` returns early when the trap runs; wait again for the solver to write and exit.
set +e
wait "$SOLVER"; STATUS=$?
while kill -0 "$SOLVER" 2>/dev/null; do wait "$SOLVER"; STATUS=$?; done
set -e

if [[ $STATUS -eq 0 ]] && ! python - "$OUT" "$SCENE" <<'PY'
import sys, csv, yaml
out, scene = sys.argv[1], sys.argv[2]
end = float(yaml.safe_load(open(scene))["time"]["end"])
rows = list(csv.DictReader(open(f"{out}/history.csv")))
sys.exit(0 if rows and float(rows[-1]["time"]) >= end * (1 - 1e-9) else 1)
PY
then
    echo "not finished: resubmitting to continue from $OUT/checkpoints/latest.h5"
    sbatch --dependency=afterany:"$SLURM_JOB_ID" "$0" "$SCENE" "$OUT"
fi
exit $STATUS
