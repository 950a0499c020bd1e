#!/bin/bash
# Strong scaling: a fixed 2M-particle settle scene on 1, 2, 4, ..., 256 ranks (4 nodes x 64 cores).
# Submit: sbatch jobs/slurm_strong.sh      Results: benchmarks/results/strong_<jobid>.{json,png}
#SBATCH --job-name=pdemfem-strong
#SBATCH --nodes=4
#SBATCH --ntasks-per-node=64
#SBATCH --cpus-per-task=1
#SBATCH --exclusive
#SBATCH --time=04:00:00
#SBATCH --output=%x-%j.out
set -euo pipefail
source "${SLURM_SUBMIT_DIR}/jobs/env.sh"
cd "$PDEMFEM_HOME"
# Each rank count is one job step on the allocation; --cpu-bind=cores pins one rank per core.
python benchmarks/scaling.py --mode strong --particles 2000000 \
    --ranks 1 2 4 8 16 32 64 128 256 --steps 500 --pre-steps 200 \
    --launcher "srun --cpu-bind=cores --exact" \
    --json "benchmarks/results/strong_${SLURM_JOB_ID}.json"
