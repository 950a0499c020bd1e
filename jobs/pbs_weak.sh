#!/bin/bash
# Weak scaling (PBS Pro / OpenPBS): 100,000 particles per rank on 1 ... 256 ranks.
# Submit: qsub jobs/pbs_weak.sh            Results: benchmarks/results/weak_<jobid>.{json,png}
#PBS -N pdemfem-weak
#PBS -l select=4:ncpus=64:mpiprocs=64
#PBS -l place=scatter:excl
#PBS -l walltime=04:00:00
#PBS -j oe
set -euo pipefail
source "${PBS_O_WORKDIR}/jobs/env.sh"
cd "$PDEMFEM_HOME"
JOB="${PBS_JOBID%%.*}"
python benchmarks/scaling.py --mode weak --per-rank 100000 \
    --ranks 1 2 4 8 16 32 64 128 256 --steps 500 --pre-steps 200 \
    --launcher "mpiexec --hostfile $PBS_NODEFILE --map-by core --bind-to core" \
    --json "benchmarks/results/weak_${JOB}.json"
