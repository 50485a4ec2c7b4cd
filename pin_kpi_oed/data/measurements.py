"""Measurement files: read, validate and write laser-tracker measurements (CSV).

A measurement is one robot configuration ``q`` together with what the tracker
saw there: the reflector position in the tracker frame and, for a 6-DoF probe,
the probe orientation. All quantities are SI: metres, radians, seconds, kg, °C.

CSV format
----------
* Plain comma-separated text, UTF-8 (a byte-order mark is accepted), ``.``
  as decimal point. The first row is a header; every following row is one
  measurement. Blank lines (or rows whose cells are all empty) are ignored.
  Header names are matched exactly (case-sensitive) after stripping spaces.
* Columns, in any order:

  ==============================  ========  ========================================
  column                          unit      meaning
  ==============================  ========  ========================================
  one per actuated joint, named   rad       joint position (for prismatic joints: m)
  exactly as in the URDF
  ``x``, ``y``, ``z``             m         reflector position in the tracker frame
                                            (required)
  ``rx``, ``ry``, ``rz``          rad       optional: orientation of a 6-DoF probe in
                                            the tracker frame as a rotation vector
                                            (axis × angle); all three or none
  ``sigma``                       m         optional: isotropic standard deviation of
                                            the position (same on x, y and z)
  ``sigma_x``, ``sigma_y``,       m         optional: per-axis standard deviation, all
  ``sigma_z``                               three or none; not together with ``sigma``
  ``temperature``                 °C        optional: ambient/robot temperature
  ``payload``                     kg        optional: payload mass
  ``time``                        s         optional: time stamp (any origin)
  ``station``                     (text)    optional: label of the measurement set-up
                                            (tracker placement) the row was taken
                                            from, text or integer (``B``, ``1``);
                                            compared as text after stripping spaces.
                                            Rows of one station share one tracker
                                            pose (and reflector); see below
  anything else                   (any)     kept as a numeric "extra" column
  ==============================  ========  ========================================

* Every cell must be a finite number (``nan``, ``inf`` or an empty cell are
  errors), except the ``station`` cells, which are labels (never empty);
  standard deviations must be > 0 and payloads >= 0.
* Stations: a file without a ``station`` column is one station. Several files
  of one calibration (``identify --data B.csv --data C.csv``) are each their
  own station (labelled by the file name without extension) unless they carry
  a ``station`` column; :func:`concat_measurements` joins them. Identification
  fits one tracker pose per station and the robot's parameters shared by all.
* ``x, y, z`` may be left out only where positions are not needed
  (``read_measurements(..., require_position=False)``, e.g. ``pin-kpi-oed
  predict`` on joint values alone); they are then NaN in the set.
* Joint columns: if ``joint_names`` is passed to :func:`read_measurements`,
  exactly those columns are the joints (in that order) and every other
  unrecognised column goes to :attr:`MeasurementSet.extra`; without it, every
  unrecognised column is a joint, in file order, and ``extra`` is empty.
* Unit guard: the file is rejected as "looks like mm/degrees" if the median
  distance ``|(x, y, z)|`` exceeds ``max(50 m, 20 × reach_m)`` (trackers stand
  a few metres from the robot; a file in mm has distances in the thousands),
  if ``reach_m`` is given and the median distance of the points from their
  median point exceeds ``20 × reach_m`` (the reflector cannot wander farther
  than about the reach), if any joint value or rotation-vector component
  exceeds ``2π + 0.1`` in magnitude (degrees), or if the median standard
  deviation exceeds 0.1 m (mm or µm).
* Units and column names as they come: ``read_measurements(..., units="mm,deg",
  columns="joint_a1=A1,x=X")`` (CLI: ``--units`` / ``--columns`` on every command that reads
  measurements) renames the file's columns first and converts the numbers to SI after parsing
  (lengths: x, y, z, sigma, prismatic joints; angles: rx, ry, rz, revolute joints). Without them
  a file in mm / degrees or with other names is refused with one line that says which option
  to use. The table is read with pandas (:mod:`pin_kpi_oed.data.table`).
* Two rows with identical joint values and identical measurement (x, y, z and,
  if present, rx, ry, rz) are duplicates and rejected.

* Tool header: comment lines (``#``) before the column header carry the tool the rows were
  measured with, one field per line, the value in JSON (``# tool_frame: "panda_link8"``;
  fields ``robot``, ``tool_frame``, ``reflector_m``, ``tcp_m``, ``q_work``;
  :mod:`pin_kpi_oed.data.tool_header`). The reader keeps them in :attr:`MeasurementSet.tool`
  (:func:`read_measurement_tool` reads them alone) and the writer writes them back; other comment
  lines there are ignored. ``identify``, ``diagnose``, ``register`` and ``simulate`` take the tool
  from them and refuse an option or a cell that contradicts them.

Example::

    shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,wrist_2_joint,wrist_3_joint,x,y,z,sigma_x,sigma_y,sigma_z,temperature
    0.1,-1.2,1.3,-0.4,1.5,0.0,0.3839712,-3.2407562,0.2017262,4.2e-05,2.2e-05,5.6e-06,21.68

:func:`write_measurements` writes the joint columns, then ``x,y,z``, then
``rx,ry,rz``, ``sigma_x,sigma_y,sigma_z``, ``temperature``, ``payload``,
``time``, ``station`` (each only if present) and finally the extra columns, with
shortest-round-trip float formatting (``repr``), so that reading the file back
gives bit-identical arrays. Per-axis sigma is always written as
``sigma_x,sigma_y,sigma_z`` (never the isotropic ``sigma``).

Files are written atomically (:func:`atomic_write_text`,
:func:`atomic_write_json`): the text goes to a temporary file in the target
directory, is flushed to disk and then renamed over the target with
:func:`os.replace`, so a reader sees either the old or the new file, never a
half-written one.

Modules: the container (:mod:`~pin_kpi_oed.data.measurement_set`), the reader
(:mod:`~pin_kpi_oed.data.measurement_reader`), the writer (:mod:`~pin_kpi_oed.data.measurement_writer`);
every public name is importable from here.
"""

from __future__ import annotations

from pin_kpi_oed.data.measurement_reader import (ANGLE_LIMIT_RAD, MAX_MEDIAN_DISTANCE_M, MAX_MEDIAN_SIGMA_M,
                                                 check_positive_sigma, parse_numeric_table,
                                                 read_measurement_tool, read_measurements)
from pin_kpi_oed.data.measurement_set import (PAYLOAD_COLUMN, POSITION_COLUMNS, RESERVED_COLUMNS, ROTVEC_COLUMNS,
                                              SIGMA_AXIS_COLUMNS, SIGMA_COLUMN, STATION_COLUMN, TEMPERATURE_COLUMN,
                                              TIME_COLUMN, MeasurementSet, concat_measurements)
from pin_kpi_oed.data.measurement_writer import write_measurements

__all__ = [
    "POSITION_COLUMNS",
    "ROTVEC_COLUMNS",
    "SIGMA_COLUMN",
    "SIGMA_AXIS_COLUMNS",
    "TEMPERATURE_COLUMN",
    "PAYLOAD_COLUMN",
    "TIME_COLUMN",
    "RESERVED_COLUMNS",
    "STATION_COLUMN",
    "MeasurementSet",
    "read_measurements",
    "read_measurement_tool",
    "write_measurements",
    "concat_measurements",
    "parse_numeric_table",
    "check_positive_sigma",
    "ANGLE_LIMIT_RAD",
    "MAX_MEDIAN_DISTANCE_M",
    "MAX_MEDIAN_SIGMA_M",
]
