"""The edges of the workbench: files, simulation, views, command lines, execution on Dask.

Rooms, each a subpackage whose ``__init__`` exports what the others may use (imports run one way,
from the commands down; see docs/architecture.md):

* ``python -m pipeline.<tool>``: the commands (``run``, ``discover``, ``design``, ``study``,
  ``blind``, ``fleet``, ``snapshot``), each a thin front end: parse, call one library function,
  print its result; :mod:`pipeline.cli` holds what they share;
* :mod:`pipeline.workflows`: the tools' library functions (settings in, result out);
* :mod:`pipeline.views`: Rerun files and their layouts, reading them back, headless snapshots;
* :mod:`pipeline.formats`: the recording format, its checks, safe writing of outputs;
* :mod:`pipeline.simulation`: the simulated lab (testbed, scenarios) over :mod:`mjcf`;
* :mod:`pipeline.execution`: many-task jobs on Dask.

The names below are imported from their rooms when first used.
"""

import os

from .execution.executor import BLAS_ENV

# One BLAS thread unless the caller says otherwise, set before NumPy loads (the executor imports no
# NumPy): the workbench's matrices are small (a few hundred rows, tens of columns), where BLAS
# threads cost more than they give; on a busy 2-core machine a threaded SVD of a 360 x 48 Jacobian
# took 0.15 s instead of 1 ms, and a --real run 23 s instead of 1.5 s. Dask workers get the same.
def one_blas_thread() -> None:
    """Set every BLAS thread count of :data:`pipeline.execution.BLAS_ENV` not already set."""
    for variable, value in BLAS_ENV.items():
        os.environ.setdefault(variable, value)


one_blas_thread()

from calib.lazy import lazy_exports  # noqa: E402

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "formats": ("Recording", "RecordingError", "read_recording", "write_recording"),
    "simulation": ("Testbed", "Measurements", "SettleError"),
})
