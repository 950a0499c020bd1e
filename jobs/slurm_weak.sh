#!/bin/bash
# Weak scaling: 100,000 particles per rank on 1 ... 256 ranks (the box footprint grows with ranks).
# Submit: sbatch jobs/slurm_weak.sh        Results: benchmarks/results/weak_<jobid>.{json,png}
#SBATCH --job-name=pdemfem-weak
#SBATCH --nodes=4
#SBATCH --ntasks-per-node=64
#SBATCH --cpus-per-task=1
#SBATCH --exclusive
#SBATCH --time=04:00:00
#SBATCH --output=%x-%j.out
set -euo pipefail
source "${SLURM_SUBMIT_DIR}/jobs/env.sh"
cd "$PDEMFEM_HOME"
python benchmarks/scaling.py --mode weak --per-rank 100000 \
    --ranks 1 2 4 8 16 32 64 128 256 --steps 500 --pre-steps 200 \
    --launcher "srun --cpu-bind=cores --exact" \
    --json "benchmarks/results/weak_${SLURM_JOB_ID}.json"
