import os
import subprocess
import sys
from pathlib import Path

import pytest

# The harness module sits beside the tests.
sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: E402,F401  (sets PETSC_DIR and the MPI environment first)

# ----------------------------------------------------------------------------------------------------------
# Every test that launches mpiexec carries @pytest.mark.mpi (so `-m "not mpi"` gives a suite that needs no MPI
# launcher).  A static look at the test's source cannot tell (tests/test_cli.py's run_command launches mpiexec
# only for ranks > 1), so the check is made where the process starts: subprocess.Popen (which subprocess.run
# uses) refuses an mpiexec/mpirun command while a test without the marker is being set up, run or torn down.
# A fixture that launched mpiexec is remembered, so the later tests that get its cached (module-scoped) value
# need the marker too.

MPI_LAUNCHERS = ("mpiexec", "mpirun", "orterun")
_original_popen = subprocess.Popen
_current_item = None
_fixture_stack = []              # fixture definitions being set up, innermost last
_launching_fixtures = set()      # fixture definitions that launched mpiexec


def _launcher(arguments) -> str:
    """The basename of the program `arguments` (a Popen args value) runs, if it is an MPI launcher, else ''."""
    words = os.fsdecode(arguments).split() if isinstance(arguments, (str, bytes, os.PathLike)) else list(arguments)
    program = os.path.basename(os.fsdecode(words[0])) if words else ""
    return program if program.startswith(MPI_LAUNCHERS) else ""


class _MarkerCheckingPopen(_original_popen):
    def __init__(self, args, *positional, **keywords):
        item, launcher = _current_item, _launcher(args)
        if item is not None and launcher:
            _launching_fixtures.update(_fixture_stack)
            _require_marker(item, launcher)
        super().__init__(args, *positional, **keywords)


def _require_marker(item, launcher) -> None:
    if item.get_closest_marker("mpi") is None:
        raise pytest.fail.Exception(f"{item.nodeid} launches {launcher} but has no @pytest.mark.mpi: add the marker "
                                    "(checked by tests/conftest.py)", pytrace=False)


def pytest_configure(config):
    subprocess.Popen = _MarkerCheckingPopen


def pytest_unconfigure(config):
    subprocess.Popen = _original_popen


@pytest.hookimpl(hookwrapper=True)
def pytest_fixture_setup(fixturedef, request):
    _fixture_stack.append(fixturedef)
    try:
        yield
    finally:
        _fixture_stack.pop()


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    definitions = getattr(getattr(item, "_fixtureinfo", None), "name2fixturedefs", {})
    if any(definition in _launching_fixtures for chain in definitions.values() for definition in chain):
        _require_marker(item, "mpiexec (through a fixture)")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    global _current_item
    _current_item = item
    try:
        yield
    finally:
        _current_item = None


def pytest_collection_modifyitems(config, items):
    # Under pytest-xdist (`make test`: one worker per core) the tests that launch mpiexec all go to one worker and
    # run one at a time: two MPI jobs at once would oversubscribe a small machine's cores, and a waiting rank
    # spins.  Without xdist the marker is not registered, and nothing is added.
    if not config.pluginmanager.hasplugin("xdist"):
        return
    for item in items:
        if item.get_closest_marker("mpi") is not None:
            item.add_marker(pytest.mark.xdist_group("mpi"))
