"""Which reader an aiding file takes, from its content (``--aiding-format auto``, the default of
``imu-learn navigate``): the one detector beside the readers.

* a ROS bag (a ``.bag`` file or a ROS 2 folder): ``bag`` (:mod:`.bag`; a topic names the stream);
* ``%`` comment lines whose last names RTKLIB's time system and position columns: ``rtklib``
  (:mod:`.rtklib`);
* otherwise the first line that is not a comment or a header of names: commas and a first cell in
  nanoseconds (an integer of 13 digits or more, or a number of 1e12 or more in float notation) ->
  ``asl``; commas -> ``csv``; white space -> ``tum`` (:mod:`.tum`).
"""
from __future__ import annotations

from pathlib import Path
from typing import List

from imu_learn.data.formats import rosbag

from .rtklib import looks_like_pos
from .tum import is_epoch_ns

FORMATS = ("tum", "csv", "asl", "rtklib", "bag")
HEAD_BYTES = 65536


def _head(path: Path) -> List[str]:
    with open(path, "rb") as fh:
        raw = fh.read(HEAD_BYTES)
    return raw.decode("utf-8", errors="replace").splitlines()[:200]


def detect(path: Path) -> str:
    """The aiding format of ``path`` (module docstring); a missing file is FileNotFoundError."""
    path = Path(path)
    if rosbag.detect(path):
        return "bag"
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    lines = _head(path)
    if looks_like_pos(lines):
        return "rtklib"
    for line in lines:
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        if "," not in text:
            return "tum"
        first = text.split(",", 1)[0].strip()
        if not any(c.isdigit() for c in first):
            continue  # a header line of names
        return "asl" if is_epoch_ns(first) else "csv"
    return "tum"
