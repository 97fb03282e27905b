"""Measured TE records of a test rig: the dataset format, importing a rig's files, and what the records show before
any model.

Modules
-------
:mod:`rvrig.dataset`, :mod:`rvrig.testgroups`
    ``read_dataset(folder, design=None)``: runs.csv + samples.csv validated (errors name the file, column and run),
    duplicates and start-up transients dropped and reported; the tests (one homing of the rig each) the runs
    belong to.
:mod:`rvrig.rigimport`, :mod:`rvrig.rigfilter`, :mod:`rvrig.cli_import`
    ``rv-calibrate import``: a rig's files (output angle and TE per direction, sampled in time) into a dataset,
    averaged down without aliasing, gaps reported.
:mod:`rvrig.rigtable`
    The per-test table (means and peak-to-peak per direction, backward minus forward, the main orders), how it
    changes with load, the measured datasheet (secant rigidity, light-load play, lost motion where the loads allow).
:mod:`rvrig.spectrum`
    Orders over the whole band the readings resolve; content locked to the reducer's orders told from lines at a
    fixed frequency.
:mod:`rvrig.orders`
    The reducer's ratio, period and base orders from its design.

The calibration of the reducer model against these records is :mod:`rvcalib`.
"""
from rvrig.dataset import MeasuredDataset, RunRecord, read_dataset

__all__ = ["MeasuredDataset", "RunRecord", "read_dataset"]
