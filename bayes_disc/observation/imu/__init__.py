"""Inertial recordings (docs/data-formats.md): reading, throw segmentation and the logging time base.

- :mod:`.formats`: :func:`read_flatball_ins`, :func:`read_imu_csv`, :func:`write_imu_csv`,
  :func:`read_imu`, :class:`InertialLog`, :class:`ImuFileError`.
- :mod:`.segmentation`: :func:`find_throws` -> :class:`Segment` (release, first impact, orientation),
  :func:`throw_logs`, :func:`landing_log` (the rows after the impact).
- :mod:`.timebase`: :func:`estimate_timebase` (row period from magnetometer/gyro, barometer cadence),
  :func:`row_offsets_from_magnetometer` (every row's time from the magnetometer's phase).
"""
from .formats import (FORMATS, G_STANDARD, ImuFileError, InertialLog, read_flatball_ins, read_imu, read_imu_csv,
                      write_imu_csv)
from .segmentation import Segment, SegmentationSettings, find_throws, flight_names, landing_log, throw_logs
from .timebase import (BaroCadence, PeriodEstimate, TimeBase, baro_cadence, estimate_timebase,
                       period_from_mag_gyro, row_offsets_from_magnetometer)

__all__ = ["FORMATS", "G_STANDARD", "BaroCadence", "ImuFileError", "InertialLog", "PeriodEstimate", "Segment",
           "SegmentationSettings", "TimeBase", "baro_cadence", "estimate_timebase", "find_throws", "flight_names",
           "landing_log", "period_from_mag_gyro", "read_flatball_ins", "read_imu", "read_imu_csv",
           "row_offsets_from_magnetometer", "throw_logs",
           "write_imu_csv"]
