"""Noise identification of an IMU from one static record (``fusionbench identify``): the Allan deviation of each
axis, the IEEE-952 terms fitted to it and an IMU spec made of what was identified.

The entry points, under one name: :func:`identify` (the numbers, :mod:`fusionbench.recording.identify_core`, where the
method and its choices are described), :func:`summary` (the lines to print), :func:`write_spec_toml`,
:func:`write_identify_report` (identify.json and allan.png) and :func:`run_identify` (all of it, for the command
line; :mod:`fusionbench.recording.identify_report`). The output folder is written whole or not at all
(:mod:`fusionbench.files.reportdir`, :data:`OUTPUT`). Imports point ``identify`` -> ``identify_report`` ->
``identify_core``.
"""

from __future__ import annotations

from fusionbench.recording.identify_core import (ADEV_UNITS, MIN_SAMPLES, MIN_TAU_S, OUTPUT, UNITS,  # noqa: F401
                                                 Identification, Term, identify, spec_table)
from fusionbench.recording.identify_report import (poor_fit_note, report_dict, run_identify, summary,  # noqa: F401
                                                   write_identify_report, write_spec_toml)

__all__ = ["MIN_SAMPLES", "MIN_TAU_S", "UNITS", "ADEV_UNITS", "OUTPUT", "Term", "Identification", "identify",
           "summary", "spec_table", "write_spec_toml", "write_identify_report", "run_identify", "poor_fit_note",
           "report_dict"]
