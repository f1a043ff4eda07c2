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

from calib.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "formats": ("Recording", "RecordingError", "read_recording", "write_recording"),
    "simulation": ("Testbed", "Measurements", "SettleError"),
})
