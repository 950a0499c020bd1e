#!/bin/bash
# Strong scaling (PBS Pro / OpenPBS): a fixed 2M-particle settle scene on 1 ... 256 ranks.
# Submit: qsub jobs/pbs_strong.sh          Results: benchmarks/results/strong_<jobid>.{json,png}
#PBS -N pdemfem-strong
#PBS -l select=4:ncpus=64:mpiprocs=64
#PBS -l place=scatter:excl
#PBS -l walltime=04:00:00
#PBS -j oe
set -euo pipefail
source "${PBS_O_WORKDIR}/jobs/env.sh"
cd "$PDEMFEM_HOME"
JOB="${PBS_JOBID%%.*}"
python benchmarks/scaling.py --mode strong --particles 2000000 \
    --ranks 1 2 4 8 16 32 64 128 256 --steps 500 --pre-steps 200 \
    --launcher "mpiexec --hostfile $PBS_NODEFILE --map-by core --bind-to core" \
    --json "benchmarks/results/strong_${JOB}.json"
