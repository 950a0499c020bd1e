import sys
from pathlib import Path

# The harness module sits beside the tests.
sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: E402,F401  (sets PETSC_DIR and the MPI environment first)
